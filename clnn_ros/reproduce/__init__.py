"""Reproduce Smith (2024): `python -m clnn_ros.reproduce` (see __main__.py), one experiment a module.

    common            the paper's numbers, run sizes, edge scan, physics modes; shared helpers
    calibration       (a)-(d) under every physics mode x integrator
    learning          the paper's learning runs (1 SV, 2 SV at two velocity edges)
    physics_modes     the learning runs under every physics mode x integrator
    open_choices      each open choice switched alone from the paper defaults
    gymnasium_physics the agent on gymnasium's CartPole-v1 physics
    figures           Figures 7-15 and their traces
    claims            paper vs measured, with the verdicts' thresholds
    report            docs/REPRODUCTION.md from the sections above
"""
