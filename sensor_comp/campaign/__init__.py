"""
Campaign scale: every shot of a lab's test campaign, on Dask, on one laptop or a cluster.

:func:`run_campaign` analyses each recording in a task, caches results by SHA-256, streams
a per-shot table and summarises each sensor's sensitivity drift. Modules: ``discover``,
``models``, ``shots``, ``table``, ``store``, ``pools``, ``engine``, ``drift``, ``summary``,
``report``; design and numbers in ``doc/campaign.md``.
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
