"""A record read and cut up: loading a CSV or bag, uniform grids, held levels and edges, periodic cycles.

``loading`` reads a rig's CSV or a bag; ``series`` holds the time-series helpers (uniform grid, held
levels, step edges, smoothing); ``periodic`` finds a command's repeated cycles; ``command_hold`` says
whether the command is held between samples or sampled from a running demand.
"""
