"""The ``sensor-comp`` command line."""
