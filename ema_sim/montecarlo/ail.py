"""Aircraft-in-the-loop runs of a campaign: the offline loop once per run, its dither measured on both wings.

Each run is :func:`ema_sim.ail.loop.run_ail` (the loop ``ema ail`` and the lockstep ROS suite run, frame
for frame) with the run's test environment (the profile's paths with the dispersed elements replaced;
``environment.<element>`` sets both paths at once), bungee and model parameters, and its own noise
seeds from (seed, run index): the test environment's and the model's. The dither is
:func:`ema_sim.ail.measure.measure` after the configuration's settling time, per wing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from ema_sim.ail.loop import AilOptions, run_ail
from ema_sim.ail.measure import measure
from ema_sim.ail.params import WINGS, load_ail_config
from ema_sim.environment import load_profile
from ema_sim.models import model_class
from ema_sim.models.high_order.models import HighOrderModel
from ema_sim.montecarlo.campaign import Campaign, nominal_values
from ema_sim.montecarlo.dispersions import FloatArray, run_seed

WING_COLUMNS = ("dither", "freq_hz", "pp_deg", "peak_db")
"""The columns of each wing (``left_wing.dither``...): verdict (1/0), frequency, peak to peak, level above the floor."""


def ail_options(c: Campaign, seed: int, run: int, values: Mapping[str, float]) -> AilOptions:
    """The loop options of one run: the campaign's profile and model with this run's values and seeds.

    Parameters
    ----------
    c : Campaign
        The campaign (``kind: ail``).
    seed : int
        Its seed.
    run : int
        The run (−1: the nominal run).
    values : mapping
        This run's dispersed values.

    Returns
    -------
    AilOptions
        What :func:`~ema_sim.ail.loop.run_ail` takes.
    """
    s = run_seed(seed, run)
    profile = load_profile(c.profile).with_seed(s % (2**31))
    paths = {"command": dict(profile.command.as_dict()), "feedback": dict(profile.feedback.as_dict())}
    for name, value in values.items():
        head, _, key = name.partition(".")
        if head in paths:
            paths[head][key] = float(value)
        elif head == "environment":
            for p in paths.values():
                p[key] = float(value)
    profile = replace(profile, command=replace(profile.command, **paths["command"]),
                      feedback=replace(profile.feedback, **paths["feedback"]))
    cfg = load_ail_config()
    bungee = values.get("setup.bungee_inlb")
    setup = cfg.setup(c.profile, bungee_inlb=None if bungee is None else float(bungee))
    own = {p.name for p in model_class(c.model).parameters()}
    overrides: dict[str, float] = {**c.fixed, **{k: float(v) for k, v in values.items() if k in own}}
    if issubclass(model_class(c.model), HighOrderModel):
        overrides["seed"] = s
    return AilOptions(profile=c.profile, model=c.model, duration_s=c.duration_s, seed=None, setup=setup,
                      config=cfg, environment=profile, model_overrides=overrides)


def ail_runs(c: Campaign, seed: int, runs: Sequence[int], values: Mapping[str, FloatArray], *,
             with_nominal: bool) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """Every run of a block through the loop, and the dither of both wings.

    Parameters
    ----------
    c : Campaign
        The campaign.
    seed : int
        Its seed.
    runs : sequence of int
        The runs.
    values : mapping
        Parameter → one value per run.
    with_nominal : bool
        Run the nominal configuration too.

    Returns
    -------
    metrics : dict
        ``<wing>.<column>`` (:data:`WING_COLUMNS`) and ``wings_dithering``, one value per run.
    nominal : dict
        The nominal run's (empty without it).
    """
    settle = load_ail_config().settle_s
    todo: list[tuple[int, dict[str, float]]] = []
    if with_nominal:
        todo.append((-1, nominal_values(c)))
    todo += [(r, {k: float(v[j]) for k, v in values.items()}) for j, r in enumerate(runs)]
    names = [f"{w}.{col}" for w in WINGS for col in WING_COLUMNS] + ["wings_dithering"]
    rows: list[list[float]] = []
    for run, vals in todo:
        found = measure(run_ail(ail_options(c, seed, run, vals)), settle, channels=WINGS)
        row: list[float] = []
        for w in WINGS:
            d = found[w]
            row += [float(d.dither), float("nan") if d.freq_hz is None else float(d.freq_hz), d.peak_to_peak_deg,
                    d.peak_db]
        row.append(float(sum(found[w].dither for w in WINGS)))
        rows.append(row)
    table = np.array(rows, dtype=float).reshape(len(rows), len(names))
    nominal = dict(zip(names, table[0].tolist(), strict=True)) if with_nominal else {}
    body = table[1:] if with_nominal else table
    return {n: body[:, i].copy() for i, n in enumerate(names)}, nominal
