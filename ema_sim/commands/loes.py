"""``ema loes``: refit a channel's low-order equivalent system to HOAD3 (sections 3.4, 4.2.8)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ema_sim.analysis.studies.loes import fit_loes, write_loes
from ema_sim.commands.common import Subparsers, add_model_args, parse_overrides


def run(args: argparse.Namespace) -> int:
    """Dwell HOAD3, fit the LOES, print it (and write it to the channel's YAML).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    fit = fit_loes(args.channel, None, None, load_inlb=args.load_inlb, **parse_overrides(args.overrides))
    c = fit.coefficients
    print(f"LOES of HOAD3, {args.channel}: wn {c['wn_rad_s']:.4g} rad/s, zeta {c['zeta']:.4g}, "
          f"delay {c['delay_s'] * 1e3:.3f} ms, DC gain {c['dc_gain_ratio']:.4g}; J = {fit.cost:.3f} "
          f"over {fit.data.freq_hz[0]:g}-{fit.data.freq_hz[-1]:g} Hz ({fit.data.freq_hz.size} dwells, "
          f"±{fit.data.amp_deg:g} deg)")
    gain, phase = fit.model_db_deg()
    print("| Hz | HOAD3 dB | LOES dB | HOAD3 deg | LOES deg |")
    print("| --- | --- | --- | --- | --- |")
    for row in zip(fit.data.freq_hz, fit.data.gain_db, gain, fit.data.phase_deg, phase, strict=True):
        print("| {:.2f} | {:.2f} | {:.2f} | {:.1f} | {:.1f} |".format(*row))
    if args.write:
        print(f"wrote {write_loes(fit)}")
    if args.json:
        Path(args.json).write_text(json.dumps(fit.as_dict(), indent=2) + "\n", encoding="utf-8")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``loes`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("loes", help="refit a channel's LOES to HOAD3's sine dwells (section 3.4)",
                       description="Sine-dwell HOAD3 (one batch instance per frequency), fit a second order "
                                   "plus delay and report the mismatch cost J.")
    add_model_args(p)
    p.add_argument("--load-inlb", type=float, default=0.0, help="hinge moment held during the dwells")
    p.add_argument("--write", action="store_true", help="store the coefficients in config/<channel>.yaml")
    p.add_argument("--json", default=None, help="also write the fit and both responses as JSON")
    p.set_defaults(func=run)
