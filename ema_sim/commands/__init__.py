"""``ema`` subcommands, one module each; every module has ``register(subparsers)``.

Add a command by adding its module name to ``COMMANDS`` (in the order ``ema --help`` lists them).
"""

COMMANDS: tuple[str, ...] = (
    "simulate",
    "compare",
    "analyze",
    "identify",
    "identify_consistency",
    "monitor",
    "fault_campaign",
    "loes",
    "acceptance",
    "bench",
    "launch",
    "bag",
    "ail",
    "montecarlo",
    "export",
    "listing",
)
