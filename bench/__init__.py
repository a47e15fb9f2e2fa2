"""Benchmarks of sensor_comp: ``./run bench`` runs them all (see README)."""
