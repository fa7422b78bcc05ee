"""Applications layer: range bands, risk-aware charging plans, calibration reports, the demo.

Imports the layers below it; nothing imports it but the CLI and the fleet layer.
"""
