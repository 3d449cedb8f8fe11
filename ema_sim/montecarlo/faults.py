"""Fault campaigns: fault kinds × sizes × maneuvers × seeds, each case simulated and watched by the monitor.

Every case runs the truth model (LOADA by default) through a maneuver under a load for ``duration_s``, with
one fault from ``onset_s`` (or none: the clean cases that count false alarms), measures its outputs the way
the aircraft-in-the-loop test environment reads them (3 mV rms noise and the 5 mV A/D quantum on the ±10 V
LVDT feedback, config/ail.yaml; the same noise on the surface angle), and hands the record to
:func:`ema_sim.monitor.watch` against the truth model's nominal parameters. Cases run on Dask like the Monte
Carlo campaigns (:mod:`.engine`'s local cluster or a scheduler), or in this process with ``workers=0``. The
table (one row a case) goes to Parquet; :func:`summarize` gives detection delays, missed detections, false
alarms per hour, the isolation confusion matrix and the re-estimation errors, and :func:`plot_campaign` their
figures.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import lfilter

from ema_sim.config import load_channel
from ema_sim.errors import EmaError
from ema_sim.faults import parse_fault
from ema_sim.faults.kinds import FloatArray
from ema_sim.io.measured import MeasuredData
from ema_sim.jsontypes import JsonObject
from ema_sim.models import create, model_class
from ema_sim.monitor import Options, from_name, learn, watch
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import Inputs, frame_inputs, run_maneuver

FEEDBACK_NOISE_V = 0.003
"""The AIL profile's feedback noise, V rms (config/ail.yaml)."""
FEEDBACK_QUANTUM_V = 0.005
"""The FMU A/D quantum, V (config/ail.yaml)."""
AIL_COMMAND_DELAY_S = 0.026
"""The AIL command path's transport delay (config/ail.yaml)."""
AIL_LAG_HZ = 50.0
"""The FMU's first-order lag on the command (config/ail.yaml)."""
FRAME_HZ = 200.0
DEFAULT_SIZES: dict[str, tuple[float, ...]] = {
    "jam": (1.0,),
    "viscous_friction": (0.25, 0.5),
    "backlash": (1.0, 2.0),
    "delay": (0.003, 0.005),
    "lvdt_bias": (0.05, 0.1),
    "lvdt_drift": (0.01, 0.02),
    "lvdt_scale": (0.01, 0.02),
    "hm_sign": (1.0,),
}
"""The kinds the second-order truth model has a stage for, at sizes the report's tolerances make meaningful."""
HIGH_ORDER_SIZES: dict[str, tuple[float, ...]] = {
    "jam": (1.0,),
    "coulomb_friction": (0.5, 1.0),
    "backlash": (1.0, 2.0),
    "torque_constant": (-0.2, -0.3),
    "current_limit": (-0.3, -0.5),
    "delay": (0.003, 0.005),
    "lvdt_bias": (0.05, 0.1),
    "linkage": (-0.3,),
    "hm_sign": (1.0,),
}
"""The kinds of the high-order truth models (hoad2, hoad3), at meaningful sizes."""
CURRENT_NOISE_A = 0.05
"""Noise on a recorded motor current, A rms (illustrative: the report does not publish the current's)."""
DEFAULT_MANEUVERS = ("sine:amp_deg=3,freq_hz=0.5,cycles=40", "sine:amp_deg=1,freq_hz=2,cycles=160")


@dataclass(frozen=True)
class Case:
    """One simulated record: the fault (kind ``none``: clean), its size, the maneuver and the noise seed."""

    kind: str
    size: float
    maneuver: str
    seed: int
    model: str = "loada"
    channel: str = "left_wing"
    load: str = "const:inlb=800"
    duration_s: float = 35.0
    onset_s: float = 25.0
    healthy_s: float = 20.0
    false_alarms_per_hour: float = 0.1
    environment: str = "feedback"
    """``feedback``: the AIL feedback's noise and quantum on the readings; ``ail``: also the AIL command path
    (26 ms, 50 Hz lag, 5 mV quantum, 3 mV noise) between the recorded FMU command and the actuator."""
    reference: str = "nominal"
    """``nominal``: the truth model's nominal parameters; ``learned``: the channel's second order learned on the
    healthy window (:func:`ema_sim.monitor.learn`)."""


def cases(kinds: dict[str, tuple[float, ...]] | None = None, maneuvers: Sequence[str] = DEFAULT_MANEUVERS,
          seeds: int = 2, clean: int = 2, **common: Any) -> list[Case]:
    """Every combination, plus ``clean`` fault-free cases per maneuver and seed.

    Parameters
    ----------
    kinds : dict[str, tuple[float, ...]] | None
        The fault kinds.
    maneuvers : Sequence[str]
        The maneuvers.
    seeds : int
        The seeds.
    clean : int
        Clean cases (no fault) per maneuver and seed, for the false-alarm rate.
    common : object
        Settings every case shares.
    """
    kinds = DEFAULT_SIZES if kinds is None else kinds
    out = [Case(k, s, m, seed, **common) for k, sizes in kinds.items() for s in sizes for m in maneuvers
           for seed in range(seeds)]
    out += [Case("none", 0.0, m, 1000 + seed, **common) for m in maneuvers for seed in range(seeds * clean)]
    return out


def measured(case: Case) -> MeasuredData:
    """The case's record as the AIL test environment measures it.

    Parameters
    ----------
    case : Case
        The case.
    """
    ch = load_channel(case.channel)
    faults = [] if case.kind == "none" else [parse_fault(f"{case.kind}:at_s={case.onset_s},size={case.size}")
                                             if case.kind != "jam" else parse_fault(f"jam:at_s={case.onset_s}")]
    rng = np.random.default_rng(case.seed)
    fmu = frame_inputs(parse_maneuver(case.maneuver), parse_load(case.load), duration_s=case.duration_s)
    seen = ail_command(fmu.command_deg, case.channel, rng) if case.environment == "ail" else fmu.command_deg
    # a high-order truth's own noise (in the loop: it dithers the friction) is the case's, not one for all
    truth = create(case.model, case.channel, **({"seed": case.seed} if model_has_current(case.model) else {}))
    rec = run_maneuver(truth, Inputs(fmu.time_s, seen, fmu.hinge_moment_inlb, fmu.duration_s), faults=faults)
    held = np.minimum(np.searchsorted(fmu.time_s, rec.time_s, side="right") - 1, fmu.time_s.size - 1)
    rec = replace(rec, command_deg=fmu.command_deg[None, held])  # the record holds the FMU's command
    n = rec.time_s.size

    def read(deg: FloatArray) -> FloatArray:
        v = np.asarray(ch.position_deg_to_v(deg)) + rng.normal(0.0, FEEDBACK_NOISE_V, n)
        return np.asarray(ch.feedback_cal(np.round(v / FEEDBACK_QUANTUM_V) * FEEDBACK_QUANTUM_V), dtype=float)

    current = rec.current_a[0] + rng.normal(0.0, CURRENT_NOISE_A, n) if model_has_current(case.model) else None
    return MeasuredData(rec.time_s, rec.command_deg[0], read(rec.position_deg[0]), read(rec.surface_deg[0]),
                        rec.hinge_moment_inlb[0], current, source=f"{case.kind}:{case.size}:{case.seed}")


def ail_command(command_deg: FloatArray, channel: str, rng: np.random.Generator,
                frame_hz: float = FRAME_HZ) -> FloatArray:
    """The FMU's frame commands as the actuator gets them through the AIL command path (config/ail.yaml).

    26 ms transport delay, the FMU's 50 Hz first-order lag, 3 mV rms noise and the 5 mV D/A quantum, on the
    ±10 V command signal.

    Parameters
    ----------
    command_deg : FloatArray
        The commands, deg.
    channel : str
        The channel.
    rng : np.random.Generator
        The random generator of the case.
    frame_hz : float
        The flight computer's frame rate, Hz.
    """
    ch = load_channel(channel)
    v = np.asarray(ch.deg_to_v(command_deg), dtype=float)
    delay = round(AIL_COMMAND_DELAY_S * frame_hz)
    v = np.concatenate([np.full(delay, v[0]), v[:-delay]]) if delay else v
    a = math.exp(-2.0 * math.pi * AIL_LAG_HZ / frame_hz)
    v = lfilter([1.0 - a], [1.0, -a], v, zi=[a * v[0]])[0]
    v = np.round((v + rng.normal(0.0, FEEDBACK_NOISE_V, v.size)) / FEEDBACK_QUANTUM_V) * FEEDBACK_QUANTUM_V
    return np.asarray(ch.command_cal.inverse(v), dtype=float)


def model_has_current(model: str) -> bool:
    """The truth model knows its motor current (the high-order ones).

    Parameters
    ----------
    model : str
        The model's name.
    """
    return bool(model_class(model).has_current)


def run_case(case: Case) -> JsonObject:
    """Simulate, measure and watch one case; one table row.

    Parameters
    ----------
    case : Case
        The case.
    """
    data = measured(case)
    t0 = time.process_time()
    ch = load_channel(case.channel)
    ref = from_name(case.model, ch) if case.reference == "nominal" else learn(data, ch, case.healthy_s)
    v = watch(data, ref, Options(healthy_s=case.healthy_s, false_alarms_per_hour=case.false_alarms_per_hour))
    cpu = time.process_time() - t0
    row: JsonObject = {**case.__dict__, "watched_s": v.watched_s, "detection_cpu_s": v.cpu_s, "cpu_s": cpu,
                           "detected": False, "false_alarm": False, "delay_s": math.nan, "isolated": "",
                           "isolated_by_fits": "",
                           "estimate": math.nan, "uncertainty": math.nan, "size_estimate": math.nan}
    if v.detections:
        d = v.detections[0]
        early = case.kind == "none" or d.time_s < case.onset_s
        row.update(detected=not early, false_alarm=early, delay_s=d.time_s - case.onset_s if not early else math.nan,
                   isolated=d.kind, isolated_by_fits=min(d.ranking, key=lambda e: e.score).kind,
                   estimate=d.estimate, uncertainty=d.uncertainty, size_estimate=d.size)
    return row


Rows = list[dict[str, Any]]


def run_campaign(all_cases: Sequence[Case], out: str | Path, *, workers: int | None = None,
                 scheduler: str | None = None) -> Rows:
    """Run the cases (on Dask unless ``workers`` is 0) and write ``cases.parquet`` under ``out``.

    Returns
    -------
    list of dict
        One row a case.

    Parameters
    ----------
    all_cases : Sequence[Case]
        Every case of the campaign.
    out : str | Path
        The output directory.
    workers : int | None
        Local Dask workers (0: in this process).
    scheduler : str | None
        A running Dask scheduler's address, instead of a local cluster.
    """
    import pyarrow as pa  # noqa: PLC0415 - Parquet only when a campaign is written
    import pyarrow.parquet as pq  # noqa: PLC0415 - the same

    if not all_cases:
        raise EmaError("a fault campaign needs at least one case")
    path = Path(out)
    path.mkdir(parents=True, exist_ok=True)
    if workers == 0 and scheduler is None:
        rows = [run_case(c) for c in all_cases]
    else:
        from ema_sim.montecarlo.engine import _client  # noqa: PLC0415 - Dask only when a cluster runs

        client, cluster = _client(scheduler, workers)
        try:
            rows = list(client.gather(client.map(run_case, list(all_cases), pure=False)))
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    pq.write_table(pa.table({k: pa.array([r[k] for r in rows]) for k in rows[0]}), path / "cases.parquet")
    return rows


def _median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None


def summarize(rows: Rows) -> JsonObject:
    """Detection delay per kind, missed detections, false alarms per hour, confusion matrix, estimate errors.

    ``isolation_top1`` is the monitor's (the fits and the signature's vote); ``isolation_top1_fits_only`` what
    the fits' scores alone would have isolated.

    Parameters
    ----------
    rows : Rows
        One row per case, as run.
    """
    faulty = [r for r in rows if r["kind"] != "none"]
    watched_h = sum(r["watched_s"] for r in rows) / 3600.0
    per_kind: dict[str, object] = {}
    for kind in sorted({r["kind"] for r in faulty}):
        g = [r for r in faulty if r["kind"] == kind]
        det = [r for r in g if r["detected"]]
        right = [r for r in det if r["isolated"] == kind]
        sized = kind not in ("jam", "hm_sign")
        rel = [abs(r["size_estimate"] - r["size"]) / abs(r["size"]) for r in right if sized]
        per_kind[kind] = {
            "cases": len(g), "detected": len(det), "missed": sum(not r["detected"] and not r["false_alarm"] for r in g),
            "delay_s_median": _median([r["delay_s"] for r in det]),
            "delay_s_max": max((r["delay_s"] for r in det), default=None),
            "delay_s_by_size": {str(sz): _median([r["delay_s"] for r in det if r["size"] == sz])
                                for sz in sorted({r["size"] for r in g})},
            "isolated_right": len(right),
            "size_error_median": _median(rel) if sized else None,
            "within_20_percent": sum(e <= 0.2 for e in rel) if sized else None,
        }
    det = [r for r in faulty if r["detected"]]
    confusion: dict[str, dict[str, int]] = {}
    for r in det:
        row = confusion.setdefault(r["kind"], {})
        row[r["isolated"]] = row.get(r["isolated"], 0) + 1
    false_alarms = sum(r["false_alarm"] for r in rows)
    return {
        "cases": len(rows), "watched_hours": watched_h, "false_alarms": false_alarms,
        "false_alarms_per_hour": false_alarms / watched_h if watched_h else None,
        "detected": len(det), "faulty_cases": len(faulty),
        "isolation_top1": sum(r["isolated"] == r["kind"] for r in det) / len(det) if det else None,
        "isolation_top1_fits_only": (sum(r["isolated_by_fits"] == r["kind"] for r in det) / len(det)
                                     if det else None),
        "cpu_share_per_channel": sum(r["detection_cpu_s"] for r in rows) / sum(r["watched_s"] for r in rows),
        "per_kind": per_kind, "confusion": confusion,
    }


def plot_campaign(rows: Rows, out: str | Path) -> list[Path]:
    """``confusion.png`` (isolated against injected kind) and ``delay.png`` (detection delay per kind).

    Parameters
    ----------
    rows : Rows
        One row per case, as run.
    out : str | Path
        The output directory.
    """
    import matplotlib as mpl  # noqa: PLC0415 - plotting only when asked

    mpl.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - the same

    path = Path(out)
    faulty = [r for r in rows if r["kind"] != "none" and r["detected"]]
    kinds = sorted({r["kind"] for r in rows} - {"none"})
    labels = kinds + sorted({r["isolated"] for r in faulty} - set(kinds))
    m = np.zeros((len(kinds), len(labels)))
    for r in faulty:
        m[kinds.index(r["kind"]), labels.index(r["isolated"])] += 1
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.imshow(m, cmap="Blues")
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            if m[i, j]:
                ax.text(j, i, f"{int(m[i, j])}", ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right")
    ax.set_yticks(range(len(kinds)), kinds)
    ax.set_xlabel("isolated")
    ax.set_ylabel("injected")
    ax.set_title("Isolation confusion matrix (detected cases)")
    fig.tight_layout()
    fig.savefig(path / "confusion.png", dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(8, 4))
    data = [np.array([r["delay_s"] for r in faulty if r["kind"] == k]) for k in kinds]
    ax.boxplot([d if d.size else np.array([np.nan]) for d in data], tick_labels=kinds)
    ax.set_yscale("log")
    ax.set_ylabel("detection delay, s")
    ax.tick_params(axis="x", rotation=45)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path / "delay.png", dpi=100)
    plt.close(fig)
    return [path / "confusion.png", path / "delay.png"]
