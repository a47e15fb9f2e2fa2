"""
Campaign scale: every shot of a lab's test campaign, on Dask, on one laptop or a cluster.

A campaign is many recordings (MCAP bags, split series, CSV exports) of many sensors over
months. :func:`run_campaign` analyses each recording in a task of its own (local worker
processes, a remote Dask cluster, or this process), streams the rows of every shot to a
per-shot table (Parquet and CSV), caches each recording's result by its SHA-256 so that a
re-run computes only what is new, and summarises each sensor's acceleration sensitivity
and its drift (trend with a confidence interval, change points) in tables and an HTML
report. The numbers per shot are the core's (:mod:`sensor_comp.core`): detection,
identification and comparison as the single-recording commands compute them.

Modules, one concept each: :mod:`.discover` (recordings and sensors), :mod:`.models` (a
model per sensor), :mod:`.shots` (one recording → rows), :mod:`.table` (the per-shot
table), :mod:`.store` (the output folder and cache), :mod:`.pools` (where tasks run),
:mod:`.engine` (the run), :mod:`.drift` (trend and change points), :mod:`.summary` and
:mod:`.report`.
"""

from .discover import CampaignError, discover, SensorMap
from .engine import run_campaign
from .models import ALL_SENSORS, IdentifyOptions, ModelFile, read_models
from .pools import SYNCHRONOUS
from .shots import ShotOptions
from .summary import CampaignSummary, SensorSummary
from .table import COLUMNS, SCHEMA

__all__ = ['ALL_SENSORS', 'COLUMNS', 'SCHEMA', 'SYNCHRONOUS', 'CampaignError',
           'CampaignSummary', 'IdentifyOptions', 'ModelFile', 'SensorMap', 'SensorSummary',
           'ShotOptions', 'discover', 'read_models', 'run_campaign']
