"""``ema`` subcommands, one module each; every module has ``register(subparsers)``.

Add a command by adding its module name to ``COMMANDS`` (in the order ``ema --help`` lists them) and each
subcommand it registers to ``SUBCOMMANDS``. ``ema X`` imports only X's module (:func:`ema_sim.cli.build_parser`),
so a command module imports what it needs at its top, and no command waits for another's libraries.
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
    "schema",
    "listing",
)

SUBCOMMANDS: dict[str, str] = {
    "simulate": "simulate",
    "compare": "compare",
    "analyze": "analyze",
    "identify": "identify",
    "identify-consistency": "identify_consistency",
    "loes": "loes",
    "acceptance": "acceptance",
    "bench": "bench",
    "launch": "launch",
    "tests": "launch",
    "bag": "bag",
    "ail": "ail",
    "montecarlo": "montecarlo",
    "monitor": "monitor",
    "fault-campaign": "fault_campaign",
    "export": "export",
    "verify": "export",
    "schema": "schema",
    "models": "listing",
    "maneuvers": "listing",
}
"""Subcommand → the module that registers it (a test holds this to what the modules register)."""
