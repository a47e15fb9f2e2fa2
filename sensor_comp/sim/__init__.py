"""The drop-hammer rig simulator: shock pulses and the sensor physics they excite."""
