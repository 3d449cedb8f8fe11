"""A node's process started ahead of need, to stand in at once when the node's process dies (``--respawn``).

``python -m ema_sim.nodes.standby MODULE ARGS...`` imports the node's module (the interpreter's start and the
imports are most of a node's start: 2 s of its 3 s, measured for an EMAC), calls its ``warm(ARGS)`` when it has
one (an EMAC loads its model's compiled kernels, most of the rest) and waits on stdin: the line ``run``
runs the node's ``main(ARGS)`` there and then; end of input ends the process. ``ema launch``
(:mod:`ema_sim.suite`) keeps one for each respawned process. It ends with the launcher however the launcher
ends (:mod:`ema_sim.nodes.lifetime`).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from ema_sim.nodes import lifetime

GO = "run"
"""The line on stdin that runs the node."""


def main(argv: Sequence[str] | None = None) -> int:
    """Import the node's module, wait for :data:`GO` on stdin, run the node.

    Parameters
    ----------
    argv : sequence of str or None
        The node's module, then its arguments (None: the process's).

    Returns
    -------
    int
        The node's exit status; 0 when stdin ended first (not needed); 2 without a module.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0].startswith("-"):
        print("usage: python -m ema_sim.nodes.standby MODULE [ARGS...]", file=sys.stderr)
        return 2
    module, rest = args[0], args[1:]
    lifetime.follow_parent()
    node = importlib.import_module(module)
    warm = getattr(node, "warm", None)
    if callable(warm):
        try:
            warm(rest)
        except Exception as exc:  # a head start only: the node reports its own errors when it runs
            print(f"standby: no head start for {module} ({type(exc).__name__}: {exc})", file=sys.stderr, flush=True)
    print(f"standby: {module} ready", flush=True)  # in the node's log: a restart from here is warm
    if sys.stdin.readline().strip() != GO:
        return 0
    sys.argv = [module, *rest]
    return int(node.main(rest))


if __name__ == "__main__":
    raise SystemExit(main())
