"""Judge ``ema analyze`` and ``ema identify`` on held-out stranger-shaped bench records, as a test engineer does.

The records come from ``test/heldout_rigs.py`` (a plant of its own: FOC current loop, speed and position
loops with limits, ball screw or gearbox, Coulomb/Stribeck friction, backlash, a logger at 70-250 Hz with
integer-ms stamps). Each record is run through both tools; every figure is then checked against the truth
of the fine-step simulation and against what a few lines of numpy on the raw record show:

- ``exit``       exit status 0 and strict JSON (no NaN/Infinity);
- ``causal``     no phase lead / negative delay beyond its stated uncertainty without a flag beside it that
                 gives a cause (logging, sampling, stamps, resampling) or disowns the figure ("not determined");
                 a fit's "on_bound" alone is not such a flag;
- ``cmd``        the command's timing (held / sampled) is not decided wrongly;
- ``phase``      harmonic phases of a profiled square within max(0.5°, 3σ) of the truth;
- ``rate``       where the speed plateaus, a rate limit within 10 % of the plateau; where the plant has no speed
                 limit and no current saturation, no rate limit that would bind on the record;
- ``settle``     no threshold / dead band / free play (half width) larger than the largest settled error
                 measured on the raw record (plus half a count): a band of half width d leaves each hold
                 somewhere inside ±d (the output coasts into it), so the median understates the band and the
                 true threshold of a plant would fail a median bound;
- ``model``      report.md and the JSON (and the console) name the same final model, term by term;
- ``halves``     no discovered term said to hold whose two halves disagree beyond their uncertainty;
- ``undecid``    no effect kept that the tool's own warning says the record cannot decide against another;
- ``resol``      position resolution within 15 % of the count grid;
- ``lcycle``     a limit cycle at rest named, with its frequency (±15 %) and amplitude (±50 %);
- ``floor``      the noise floor taken where the output cannot move (≤ 2× the truth's rest floor or one
                 count), or stated as an upper bound;
- ``drift``      a bandwidth that falls / a delay that wanders reported as changing with its trend, and no
                 effect added as a proxy for it;
- ``jitter``     the jitter-only record: nothing added, the jitter named;
- ``corr``       correlations within ±1;  ``sigma0``  no ±1σ of exactly 0 presented as a figure;
- ``units``      an mm record never printed in ° or deg (phase angles excepted);
- ``channel``    no X-43A channel's travel or calibration used for a record that has none.

    python bench/truthful.py [--set heldout|dev] [--out DIR] [--cases a,b] [--seeds 100,101] [--jobs 2]

Writes ``records/`` (CSV + truth), ``runs/`` (each tool's JSON, report, console), ``summary.json`` and
``summary.md`` in ``--out``, and prints the table.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import math
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
import heldout_rigs as rigs  # noqa: E402

EMA = ROOT / ".venv" / "bin" / "ema"
X43A_CHANNELS = ("left_wing", "right_wing", "left_rudder", "right_rudder", "cowl_door")
CHECKS = ("exit", "causal", "cmd", "phase", "rate", "settle", "model", "halves", "undecid", "resol", "lcycle",
          "floor", "drift", "jitter", "corr", "sigma0", "units", "channel")
PASS, FAIL, NA = "PASS", "FAIL", "n.a."


# ------------------------------------------------------------------------------------------ raw record
def read_record(path: Path) -> dict[str, Any]:
    """Load the CSV as the engineer does: metadata, columns."""
    meta: dict[str, str] = {}
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while lines[i].startswith("#"):
        k, _, v = lines[i].lstrip("#").partition(":")
        meta[k.strip()] = v.strip()
        i += 1
    header = lines[i].split(",")
    data = np.array([[float(c) for c in ln.split(",")] for ln in lines[i + 1:] if ln.strip()])
    cols = {h: data[:, j] for j, h in enumerate(header)}
    unit = "mm" if any(h.endswith("_mm") for h in header) else "deg"
    return {"meta": meta, "cols": cols, "t": cols["time_s"], "cmd": cols[f"command_{unit}"],
            "pos": cols[f"position_{unit}"], "cur": cols.get("current_a"), "unit": unit}


def count_grid(pos: np.ndarray) -> float | None:
    """The position's count: the smallest common step between the levels it takes.

    An encoder of 0.0547 logged to 0.01 takes levels 0.05 and 0.06 apart, 0.0547 on average.
    """
    d = np.abs(np.diff(pos))
    if np.count_nonzero(d > 1e-9) < 20:
        return None
    levels = np.unique(np.round(pos, 9))
    sp = np.round(np.diff(levels), 9)
    vals, cnt = np.unique(sp, return_counts=True)
    common = vals[cnt >= max(3, 0.02 * sp.size)]
    if common.size == 0:
        return None
    q0 = common[0]
    near = (sp >= 0.5 * q0) & (sp <= 1.45 * q0)
    return float(np.mean(sp[near]))


def rests(t: np.ndarray, cmd: np.ndarray, min_s: float = 0.4) -> list[tuple[int, int]]:
    """Index ranges where the logged command is constant for at least ``min_s``."""
    out = []
    i, n = 0, cmd.size
    while i < n:
        j = i
        while j + 1 < n and cmd[j + 1] == cmd[i]:
            j += 1
        if t[j] - t[i] >= min_s:
            out.append((i, j + 1))
        i = j + 1
    return out


def settled_error(r: dict[str, Any]) -> dict[str, Any] | None:
    """The error left at the end of each hold (last 30 % of it): its |median| per hold, their median and largest."""
    seg = rests(r["t"], r["cmd"])
    if len(seg) < 3:
        return None
    errs = []
    for a, b in seg:
        k = a + int(0.7 * (b - a))
        errs.append(float(np.median(r["pos"][k:b] - r["cmd"][k:b])))
    return {"median_abs": float(np.median(np.abs(errs))), "max_abs": float(np.max(np.abs(errs))),
            "holds": len(errs), "each": errs[:12]}


def speed_plateau(r: dict[str, Any]) -> dict[str, Any]:
    """Differentiate the position and look whether the speed sits flat at one value on the large moves."""
    t, x = r["t"], r["pos"]
    v = np.diff(x) / np.diff(t)
    av = np.abs(v)
    top = float(np.percentile(av, 99.0))
    if top <= 0:
        return {"exists": False}
    near = av > 0.88 * top
    runs, k = [], 0
    while k < near.size:
        if near[k]:
            j = k
            while j < near.size and near[j]:
                j += 1
            if j - k >= 3:
                runs.append(float(np.median(av[k:j])))
            k = j
        else:
            k += 1
    exists = len(runs) >= 3 and float(np.std(runs)) < 0.06 * float(np.median(runs))
    return {"exists": exists, "value": float(np.median(runs)) if runs else None, "runs": len(runs),
            "peak": float(av.max())}


def rest_line(r: dict[str, Any]) -> dict[str, Any] | None:
    """A spectral line at rest (position), and the current's swing there."""
    seg = [(a + (b - a) // 3, b) for a, b in rests(r["t"], r["cmd"], 1.0)]
    if not seg:
        return None
    freqs, amps, cur = [], [], []
    for a, b in seg:
        x = r["pos"][a:b] - np.mean(r["pos"][a:b])
        dt = float(np.median(np.diff(r["t"][a:b])))
        n = x.size
        spec = np.abs(np.fft.rfft(x * np.hanning(n), 8 * n))
        f = np.fft.rfftfreq(8 * n, dt)
        k = int(np.argmax(spec * (f > 2.0)))
        freqs.append(float(f[k]))
        amps.append(float(0.5 * (np.percentile(x, 98) - np.percentile(x, 2))))
        if r["cur"] is not None:
            cur.append(float(np.std(r["cur"][a:b])))
    return {"freq_hz": float(np.median(freqs)), "amplitude": float(np.median(amps)),
            "current_rms_a": float(np.median(cur)) if cur else None}


def numpy_lag_ms(r: dict[str, Any]) -> float | None:
    """The delay that best maps the logged command onto the position (both on the stamps, interpolated), ms."""
    t, c, x = r["t"], r["cmd"], r["pos"]
    if np.ptp(c) == 0:
        return None
    taus = np.arange(-0.03, 0.0601, 0.0005)
    err = [float(np.mean((x - np.interp(t - tau, t, c)) ** 2)) for tau in taus]
    return float(taus[int(np.argmin(err))] * 1e3)


def raw_facts(r: dict[str, Any]) -> dict[str, Any]:
    dts = np.diff(r["t"]) * 1e3
    return {"samples": int(r["t"].size), "stamp_ms": {"median": float(np.median(dts)), "min": float(dts.min()),
                                                      "max": float(dts.max()), "std": float(np.std(dts))},
            "count_grid": count_grid(r["pos"]), "settled": settled_error(r), "plateau": speed_plateau(r),
            "rest_line": rest_line(r), "lag_ms": numpy_lag_ms(r)}


# ------------------------------------------------------------------------------------------ helpers
def strict_load(text: str) -> Any:
    def bad(name: str) -> Any:
        raise ValueError(f"non-strict JSON constant {name}")
    return json.loads(text, parse_constant=bad)


def walk(obj: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Any]]:
    yield path, obj
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from walk(v, (*path, str(k)))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from walk(v, (*path, str(i)))


def strings(obj: Any) -> list[str]:
    return [v for _, v in walk(obj) if isinstance(v, str)]


def num(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def near(value: float | None, truth: float, tol: float) -> bool:
    return value is not None and truth != 0 and abs(value / truth - 1.0) <= tol


def res(status: str, why: str = "") -> dict[str, str]:
    return {"status": status, "why": why[:600]}


LEAD_WORDS = re.compile(r"\blead|caus|negative delay|ahead of|before its command|cannot lead|never lead", re.I)
CAUSE_WORDS = re.compile(r"sampl|\bheld\b|logg|resampl|filtered|stamp|timing|skew", re.I)
"""A flag on a lead must give its likely cause: the logging, a resampling, a filtered demand."""


# --------------------------------------------------------------------------------------- the checks
def check_causal(tool: str, doc: dict[str, Any]) -> dict[str, str]:  # noqa: PLR0912 - one branch per kind of figure
    bad, flagged = [], []
    if tool == "analyze":
        for rec in doc.get("records", []):
            for path, d in walk(rec):
                if not isinstance(d, dict) or any(p in ("command", "causality") for p in path):
                    continue
                local = " ".join(str(d.get(k, "")) for k in ("note", "quality_note", "statement", "notes"))
                disowned = d.get("quality") in ("not_determined", "unreliable", "bad", "rejected")
                ok_flag = disowned or bool(LEAD_WORDS.search(local) or CAUSE_WORDS.search(local))
                ph, sg = d.get("phase_deg"), d.get("phase_sigma_deg")
                if sg is None and isinstance(d.get("random_error"), list):  # normalised random error, rad
                    sg = [math.degrees(e) if num(e) is not None else None for e in d["random_error"]]
                phs = ph if isinstance(ph, list) else [ph]
                sgs = sg if isinstance(sg, list) else [sg] * len(phs)
                fq = d.get("freq_hz")
                fqs = fq if isinstance(fq, list) else [fq] * len(phs)
                for p_, s_, f_ in zip(phs, sgs, fqs, strict=False):
                    p, s = num(p_), num(s_) or 0.0
                    if p is not None and 0.0 < p <= 90.0 and p > max(2 * s, 0.01):
                        item = (f"{'/'.join(path)} phase {p:+.3g}° ± {s:.2g} at {num(f_) or 0:.3g} Hz "
                                f"(quality {d.get('quality')})")
                        (flagged if ok_flag else bad).append(item)
                for k, v in d.items():
                    if not re.search(r"delay|(^|_)lag(_|$)", k) or k.endswith("sigma"):
                        continue
                    if isinstance(v, dict) and "value" in v:
                        val, s = num(v.get("value")), num(v.get("sigma")) or 0.0
                        own = f"{v.get('statement', '')} {v.get('note', '')}"
                        fl = (ok_flag or v.get("quality") in ("not_determined", "unreliable", "bad", "rejected")
                              or bool(LEAD_WORDS.search(own) or CAUSE_WORDS.search(own)))
                    else:
                        val, s, fl = num(v), 0.0, ok_flag
                    if val is None:
                        continue
                    scale = 1e-3 if k.endswith("_ms") else 1.0
                    if val * scale < -max(2 * s * scale, 1e-4):
                        item = f"{'/'.join(path)}/{k} = {val:.4g} ± {s:.2g} (quality {d.get('quality')})"
                        (flagged if fl else bad).append(item)
    else:
        warn = [w for w in doc.get("warnings", []) or [] if "delay" in w or LEAD_WORDS.search(w)]
        fl = any(LEAD_WORDS.search(w) or CAUSE_WORDS.search(w) for w in warn)
        fin = doc.get("final", {}) or {}
        unc = fin.get("uncertainty", {}) or {}
        cands = [("final", k, num(v), num(unc.get(k)) or 0.0)
                 for k, v in (fin.get("params") or {}).items() if "delay" in k]
        for a in doc.get("added", []) or []:
            for k, v in (a.get("params") or {}).items():
                if "delay" in k:
                    sig = num((a.get("uncertainty") or {}).get(k)) or 0.0
                    cands.append((f"added {a.get('effect')}", k, num(v), sig))
        for where, k, v, s in cands:
            if v is not None and v < -max(2 * s, 1e-4):
                (flagged if fl else bad).append(f"{where} {k} = {v:.4g} ± {s:.2g}")
    if bad:
        return res(FAIL, "; ".join(bad[:4]))
    return res(PASS, ("flagged: " + "; ".join(flagged[:3])) if flagged else "")


def check_cmd(tool: str, doc: dict[str, Any], truth: dict[str, Any]) -> dict[str, str]:
    want = truth.get("command_logging")
    if tool == "analyze":
        c = (doc.get("records") or [{}])[0].get("command") or {}
        got, decided = c.get("assumed"), c.get("decided")
    else:
        c = doc.get("command") or {}
        got, decided = c.get("fitted_as"), c.get("decided")
    if got is None:
        return res(NA, "no command decision exposed")
    if decided is False:
        return res(PASS, f"undecided, fitted as {got} (truth {want})")
    if got != want:
        return res(FAIL, f"command decided {got!r}; truth: {want} ({(c.get('evidence') or '')[:200]})")
    return res(PASS, f"{got}")


def check_phase(tool: str, doc: dict[str, Any], truth: dict[str, Any]) -> dict[str, str]:
    harm = truth.get("harmonics")
    if not harm or tool != "analyze":
        return res(NA)
    rec = (doc.get("records") or [{}])[0]
    resp = [r for p in rec.get("periodic") or [] for r in p.get("response") or []]
    if not resp:
        return res(FAIL, "no harmonic phase reported for the profiled square")
    bad, seen = [], []
    for fstr, tr in harm.items():
        f = float(fstr)
        match = [r for r in resp if num(r.get("freq_hz")) and abs(r["freq_hz"] - f) < 0.05 * f]
        if not match:
            bad.append(f"{f:g} Hz not reported")
            continue
        r = match[0]
        p, s = num(r.get("phase_deg")), num(r.get("phase_sigma_deg")) or 0.0
        seen.append(f"{f:g} Hz {p:+.2f}° (truth {tr['phase_deg']:+.2f}°)")
        if p is None or abs(p - tr["phase_deg"]) > max(0.5, 3 * s):
            bad.append(f"{f:g} Hz: reported {p}° ± {s:.2g}, truth {tr['phase_deg']:+.2f}°")
    return res(FAIL if bad else PASS, "; ".join(bad or seen))


def _identify_rate(doc: dict[str, Any]) -> float | None:
    fin = (doc.get("final") or {}).get("params") or {}
    for k, v in fin.items():
        if re.search(r"rate_(limit_)?dps$", k) and num(v):
            return num(v)
    return None


def check_rate(tool: str, doc: dict[str, Any], truth: dict[str, Any], raw: dict[str, Any]) -> dict[str, str]:
    tr = truth.get("speed_limit")
    pl = raw["plateau"]
    if tool == "analyze":
        s = (doc.get("records") or [{}])[0].get("slew") or {}
        got = num(s.get("rate")) or num((s.get("plateau") or {}).get("rate"))
    else:
        got = _identify_rate(doc)
    if tr is None:
        # no speed limit and no current saturation in the plant: a rate limit that would bind here is invented
        clean = not (truth.get("current_limit_effect") or {}).get("rms")
        peak = pl.get("peak") or 0.0
        if clean and got is not None and got < 0.95 * peak:
            return res(FAIL, f"rate limit {got:.4g} reported on a record whose speed never plateaus (no limit in the "
                             f"plant; numpy peak speed {peak:.4g})")
        return res(NA, f"no speed limit in the record (reported {got})")
    if not pl.get("exists"):
        return res(NA, f"numpy sees no plateau on the logged record ({pl})")
    if tool == "analyze":
        where = f"slew: {s.get('statement', '')}"
    else:
        rej = [f"{r.get('effect')} {r.get('value')}: {r.get('reason')}" for r in doc.get("rejected") or []
               if "rate" in str(r.get("effect"))]
        where = f"final params {(doc.get('final') or {}).get('params')}; rejected: {'; '.join(rej)[:200]}"
    ok = near(got, tr, 0.10)
    return res(PASS if ok else FAIL,
               f"reported {got}; plateau truth {tr:.1f} (numpy on record {pl.get('value', 0):.1f}); {where}")


THRESH_KEYS = re.compile(r"threshold|dead_?band|dead_?zone|free_?play|width|backlash", re.I)


def check_settle(tool: str, doc: dict[str, Any], truth: dict[str, Any], raw: dict[str, Any]) -> dict[str, str]:
    if truth.get("backlash"):
        return res(NA, "the plant has real backlash (limit-cycle case)")
    se = raw["settled"]
    if se is None:
        return res(NA, "no holds to measure a settled error on")
    q = truth.get("position_count") or 0.0
    limit = se["max_abs"] + 0.5 * q
    found = []
    if tool == "analyze":
        rec = (doc.get("records") or [{}])[0]
        for key in ("static_threshold", "dynamic_threshold"):
            for r in rec.get(key) or []:
                v = num(r.get("onset_deg"))
                if v is not None:
                    found.append((f"{key}.onset", v))
        for r in rec.get("free_play") or []:
            v = num(r.get("width_deg"))
            if v is not None:
                found.append(("free_play.width/2", v / 2))
    else:
        for k, v in ((doc.get("final") or {}).get("params") or {}).items():
            if THRESH_KEYS.search(k) and num(v) is not None:
                found.append((f"final {k}" + ("/2" if "width" in k else ""), num(v) / (2 if "width" in k else 1)))
    bad = [f"{k} = {v:.4g}" for k, v in found if abs(v) > limit * (1.0 + 1e-6)]  # at the bound is within it
    why = (f"largest settled error on the raw record {se['max_abs']:.4g} (median {se['median_abs']:.4g}) "
           f"over {se['holds']} holds "
           f"(+½ count → {limit:.4g})")
    if bad:
        return res(FAIL, "; ".join(bad) + " > " + why)
    return res(PASS, (", ".join(f"{k} {v:.3g}" for k, v in found) or "none reported") + "; " + why)


def _md_section(md: str, title: str) -> str:
    m = re.search(rf"^## {re.escape(title)}\s*$(.*?)(?=^## |\Z)", md, re.M | re.S)
    return m.group(1) if m else ""


def check_model(tool: str, doc: dict[str, Any], md: str | None, console: str) -> dict[str, str]:  # noqa: PLR0912
    if tool != "identify":
        return res(NA)
    if md is None:
        return res(FAIL, "no report.md written")
    fin = doc.get("final") or {}
    model = str(fin.get("model", ""))
    base = str((doc.get("baseline") or {}).get("model", ""))
    head, _, disc = model.partition("discovered:")
    effects = [p.strip() for p in head.split(" + ") if p.strip() and p.strip() != base]
    terms: list[str] = []
    for c in ((doc.get("discovered") or {}).get("closures") or []):
        if c.get("kept"):
            for ts in (c.get("terms") or {}).values():
                terms += [t.get("term") for t in ts if t.get("term")]
    problems = []
    if "discovered" in model and not terms:
        terms = [x.strip() for x in re.split(r",\s*", disc) if x.strip()]
    for e in effects:
        if e not in md:
            problems.append(f"effect {e!r} of the JSON's final model not in report.md")
    for t in dict.fromkeys(terms):
        if t not in md:
            problems.append(f"discovered term {t!r} ({model!r}) not in report.md")
        if t not in console:
            problems.append(f"discovered term {t!r} not on the console")
    if (effects or terms) and re.search(r"Effects added\s*\n\s*\nNone", md):
        problems.append("report.md says 'Effects added: None' while the final model is " + repr(model))
    table = _md_section(md, "Final parameters")
    rows = dict(re.findall(r"^\|\s*([A-Za-z0-9_·|()\[\]./ -]+?)\s*\|\s*([-+0-9.eE]+)\s*\|", table, re.M))
    for k, v in (fin.get("params") or {}).items():
        x = num(v)
        if x is None:
            continue
        if k not in rows:
            problems.append(f"final parameter {k} = {x:.4g} missing from report.md's final table")
        else:
            y = float(rows[k])
            if abs(y - x) > 1e-4 * max(abs(x), 1e-12) + 1e-12:
                problems.append(f"{k}: report.md {y:g} vs JSON {x:g}")
    rows = {k: v for k, v in rows.items() if k.strip("- ")}
    extra = [k for k in rows if k not in (fin.get("params") or {}) and k not in ("parameter",)]
    if extra:
        problems.append(f"report.md's final table has {extra} that the JSON's final params lack")
    return res(FAIL if problems else PASS, "; ".join(problems[:4]) or f"{model}")


def check_halves(tool: str, doc: dict[str, Any]) -> dict[str, str]:
    if tool != "identify":
        return res(NA)
    disc = doc.get("discovered") or {}
    bad, n = [], 0
    for o, out in (disc.get("outputs") or {}).items():
        for t in out.get("terms") or []:
            if not t.get("holds"):
                continue
            n += 1
            halves = t.get("halves") or []
            sig = [num(s) or 0.0 for s in t.get("uncertainty") or []]
            if len(halves) != 2:
                continue
            for j, (h0, h1) in enumerate(zip(halves[0], halves[1], strict=False)):
                a, b = num(h0), num(h1)
                if a is None or b is None:
                    continue
                s = sig[j] if j < len(sig) else 0.0
                ratio = max(abs(a), abs(b)) / max(min(abs(a), abs(b)), 1e-300)
                if abs(a - b) > 6 * s or (a * b < 0 and abs(a - b) > 2 * s) or (ratio > 3 and abs(a - b) > 2 * s):
                    bad.append(f"{o} {t.get('term')}: halves {a:.3g} / {b:.3g} (±{s:.2g} whole record) marked holding")
    if not n:
        return res(NA, "no discovered term said to hold")
    return res(FAIL if bad else PASS, "; ".join(bad[:3]))


EFFECTS = ("command_bias", "command_gain", "compliance", "current_limit", "feedback_filter", "free_play",
           "hinge_moment_sign", "hysteretic_damping", "lag_filter", "linkage_mode", "load_rate_limit",
           "nonlinear_compliance", "quantization", "rate_limit", "servo_compliance", "servo_integral",
           "static_threshold", "time_delay")


def check_undecided(tool: str, doc: dict[str, Any]) -> dict[str, str]:
    """No effect kept that the tool's own warning says the record cannot decide (against another effect)."""
    if tool != "identify":
        return res(NA)
    kept = {a.get("effect") for a in doc.get("added") or []}
    bad = []
    for w in doc.get("warnings") or []:
        if not re.search(r"cannot (decide|tell|determine)|undecid|told apart", w):
            continue
        named = {e for e in EFFECTS if re.search(rf"\b{e}\b", w)}
        if named & kept and (len(named) > 1 or re.search(r"cannot decide (whether|if)", w)):
            bad.append(w[:300])
    return res(FAIL if bad else PASS, "; ".join(bad[:2]))


def _resolution(tool: str, doc: dict[str, Any]) -> float | None:
    if tool == "analyze":
        r = (doc.get("records") or [{}])[0].get("resolution_deg") or {}
    else:
        r = doc.get("resolution_deg") or {}
    for k in ("position_deg", "position_mm", "position"):
        if k in r:
            return num(r[k])
    return None


def check_resol(tool: str, doc: dict[str, Any], truth: dict[str, Any], raw: dict[str, Any]) -> dict[str, str]:
    q = truth.get("resolution")
    if not q:
        return res(NA)
    got = _resolution(tool, doc)
    ok = near(got, q, 0.15)
    return res(PASS if ok else FAIL, f"reported {got}; count {q:.5g} (numpy grid on the record {raw['count_grid']})")


NUM_HZ = re.compile(r"(\d+(?:\.\d+)?)\s*Hz")
NUM = re.compile(r"(?<![\w.])[-±+]?(\d+(?:\.\d+)?(?:e-?\d+)?)")


def check_lcycle(truth: dict[str, Any], texts: list[str]) -> dict[str, str]:
    lc = truth.get("limit_cycle")
    if not lc:
        return res(NA)
    f0, a0 = lc["freq_hz"], lc["amplitude"]
    amps = (a0, lc["rms"], 2 * a0)
    named = [s for s in texts if re.search(r"limit.cycle|hunting|hunts", s, re.I)]
    for s in named:
        fs = [float(x) for x in NUM_HZ.findall(s)]
        ns = [float(x) for x in NUM.findall(s)]
        if any(abs(f / f0 - 1) <= 0.15 for f in fs) and any(any(abs(n / a - 1) <= 0.5 for a in amps) for n in ns):
            return res(PASS, s[:300])
    if named:
        return res(FAIL, f"named without matching frequency {f0:.1f} Hz / amplitude ±{a0:.3g}: {named[0][:250]}")
    return res(FAIL, f"no limit cycle named; truth {f0:.1f} Hz ±{a0:.3g} (rms {lc['rms']:.3g}), "
                     f"current rms {lc['current_rms_a']:.2f} A")


def _noise(tool: str, doc: dict[str, Any]) -> float | None:
    r = ((doc.get("records") or [{}])[0].get("noise_deg") if tool == "analyze" else doc.get("noise_deg")) or {}
    return num(r.get("position_deg"))


def check_floor(tool: str, doc: dict[str, Any], truth: dict[str, Any], texts: list[str]) -> dict[str, str]:
    if truth["case"] not in ("noise_grows_sweep_mm", "limit_cycle_mm"):
        return res(NA)
    got = _noise(tool, doc)
    floor = truth["rest_noise_rms"]
    lim = max(2 * floor, truth.get("position_count") or 0.0)
    if got is not None and got <= lim:
        return res(PASS, f"noise {got:.4g} vs rest floor {floor:.4g}")
    bound = [s for s in texts if re.search(r"upper bound|at most", s, re.I) and re.search(r"noise|floor", s, re.I)]
    if bound:
        return res(PASS, f"noise {got} stated as an upper bound: {bound[0][:200]}")
    return res(FAIL, f"noise floor reported {got}; where the output cannot move it is {floor:.4g} "
                     f"(≤ {lim:.4g} accepted)")


PROXY = ("rate_limit", "load_rate_limit", "current_limit", "static_threshold", "free_play", "quantization")


def check_drift(tool: str, doc: dict[str, Any], truth: dict[str, Any], texts: list[str]) -> dict[str, str]:
    trend = truth.get("trend")
    if not trend:
        return res(NA)
    if trend == "falling":
        pat_p = re.compile(r"bandwidth|ω\s*n|\bwn\b|wn_rad_s|natural frequency", re.I)
        pat_t = re.compile(r"\bfall|falls|falling|drops?|decreas|declin|lower in the (second|later)|slows", re.I)
    else:
        pat_p = re.compile(r"delay", re.I)
        pat_t = re.compile(r"wander|vari(es|ing|able)|chang(es|ing) (over|across|along|through|during)|drift|"
                           r"not constant|trend|between the halves|(first|second|later) half|over the record|"
                           r"from [\d.]+ ?(ms )?(to|→) [\d.]+ ?ms", re.I)
    hits = [s for s in texts if pat_p.search(s) and pat_t.search(s)]
    proxies = ([a.get("effect") for a in (doc.get("added") or []) if a.get("effect") in PROXY]
               if tool == "identify" else [])
    tr = truth.get("bandwidth_hz") or truth.get("delay_ms")
    if not hits:
        what = "falling bandwidth" if trend == "falling" else "wandering delay"
        return res(FAIL, f"no {what} reported (truth {tr})"
                   + (f"; proxies added: {proxies}" if proxies else ""))
    if proxies:
        return res(FAIL, f"trend named but {proxies} added as a proxy: {hits[0][:200]}")
    return res(PASS, hits[0][:300])


def check_jitter(tool: str, doc: dict[str, Any], truth: dict[str, Any], texts: list[str]) -> dict[str, str]:
    if truth["case"] != "jitter_only":
        return res(NA)
    named = [s for s in texts if re.search(r"jitter", s, re.I)]
    problems = []
    if tool == "identify":
        added = [f"{a.get('effect')} {a.get('params')}" for a in doc.get("added") or []]
        kept = [c.get("where") for c in ((doc.get("discovered") or {}).get("closures") or []) if c.get("kept")]
        if added:
            problems.append(f"added {added}")
        if kept:
            problems.append(f"discovered terms kept ({kept}): {(doc.get('final') or {}).get('model')}")
    else:
        s = (doc.get("records") or [{}])[0].get("slew") or {}
        if num(s.get("rate")):
            problems.append(f"a rate limit {s.get('rate')} reported: {s.get('statement')}")
    if not named:
        problems.append("jitter never mentioned")
    return res(FAIL if problems else PASS, "; ".join(problems) or named[0][:200])


def check_corr(doc: dict[str, Any]) -> dict[str, str]:
    bad, n = [], 0
    for path, v in walk(doc):
        if (any(re.search(r"correlation|^rho$|^r$", p) for p in path[-3:]) and num(v) is not None
                and not any(p in ("independence", "whiteness") for p in path)):
            n += 1
            if abs(num(v)) > 1.0 + 1e-9:
                bad.append(f"{'/'.join(path)} = {v}")
    if not n:
        return res(NA, "no correlation reported")
    return res(FAIL if bad else PASS, "; ".join(bad[:4]) or f"{n} correlations within ±1")


ZERO_PM = re.compile(r"±\s*0(?:\.0*)?(?![\d.eE])(?!\s*%?\s*(?:of|\)))")


def check_sigma0(tool: str, doc: dict[str, Any], texts: list[str]) -> dict[str, str]:  # noqa: PLR0912
    bad = []
    if tool == "identify":
        fin = doc.get("final") or {}
        for k, v in (fin.get("uncertainty") or {}).items():
            if num(v) == 0.0 and k not in (fin.get("not_determined") or []):
                bad.append(f"final uncertainty {k} = 0")
        for a in doc.get("added") or []:
            for k, v in (a.get("uncertainty") or {}).items():
                if num(v) == 0.0:
                    bad.append(f"added {a.get('effect')} ±1σ {k} = 0")
    for path, d in walk(doc):
        if isinstance(d, dict):
            if "value" in d and "sigma" in d and num(d.get("value")) is not None and num(d.get("sigma")) == 0.0:
                bad.append(f"{'/'.join(path)}: {d.get('value'):.4g} ± 0")
            for k, v in d.items():
                m = re.match(r"(.*)_sigma(_.*)?$", k)
                if m and num(v) == 0.0:
                    base = m.group(1) + (m.group(2) or "")
                    if num(d.get(base)) is not None:
                        bad.append(f"{'/'.join(path)}/{base} = {d.get(base):.4g} ± 0")
    for s in texts:
        m = ZERO_PM.search(s)
        if m:
            bad.append(f"text: …{s[max(0, m.start() - 60):m.end() + 10]}…")
    return res(FAIL if bad else PASS, "; ".join(list(dict.fromkeys(bad))[:4]))


DEG_WORD = re.compile(r"(?<![_A-Za-z*])(deg|dps|°/s|deg/s)(?![_A-Za-z])")
DEG_SIGN = re.compile(r"[-+±]?\d[\d.]*(?:e-?\d+)?\s*°(?!/s)")


def check_units(unit: str, lines: list[str]) -> dict[str, str]:
    if unit == "deg":
        return res(NA)
    bad = []
    for s in lines:
        for m in DEG_WORD.finditer(s):
            bad.append(f"{m.group(0)!r} in: {s[max(0, m.start() - 60):m.end() + 30].strip()}")
        for m in DEG_SIGN.finditer(s):
            window = s[max(0, m.start() - 80):m.start()]
            if not re.search(r"phase|lead|lag\b|angle", window, re.I) and not re.search(r"Hz:[-+\d.\s/]*$", window):
                bad.append(f"{m.group(0)!r} in: {s[max(0, m.start() - 60):m.end() + 20].strip()}")
    return res(FAIL if bad else PASS, "; ".join(list(dict.fromkeys(bad))[:4]))


def check_channel(tool: str, doc: dict[str, Any], texts: list[str]) -> dict[str, str]:
    ch = (doc.get("records") or [{}])[0].get("channel") if tool == "analyze" else doc.get("channel")
    why = []
    if tool == "identify":
        tr = doc.get("travel_deg") or {}
        src = str(tr.get("source", ""))
        if src and src not in ("data", "record", "measured") and not re.search(r"data|record|measured", src):
            why.append(f"travel from {src!r}: {tr.get('used')}")
    if ch in X43A_CHANNELS:
        said = [s for s in texts if ch in s and re.search(r"stand-in|generic|no channel", s)]
        uses = [s for s in said if re.search(r"configuration used|calibration", s)]
        if not said:
            why.append(f"channel {ch} used silently")
        elif uses:
            why.append(f"runs as X-43A channel {ch!r}, not a generic actuator: {uses[0][:160]}")
    return res(FAIL if why else PASS, "; ".join(why) or f"channel {ch}")


# ---------------------------------------------------------------------------------------------- runs
def run_tool(tool: str, csv: Path, truth: dict[str, Any], out: Path, timeout: float) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    cmd = [str(EMA), tool, str(csv), "--json", str(out / f"{tool}.json"), "--report", str(out / f"{tool}_report")]
    if truth.get("columns_arg"):
        cmd += ["--columns", truth["columns_arg"]]
    if tool == "identify":
        cmd += ["--workers", "1"]
    env = dict(os.environ, NUMBA_NUM_THREADS="1", MPLBACKEND="Agg")
    t0 = time.monotonic()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, cwd=str(out), check=False)
        rc, so, se = p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as exc:
        so = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        rc, se = -9, f"timeout after {timeout:.0f} s"
    dt = time.monotonic() - t0
    (out / f"{tool}.stdout").write_text(so, encoding="utf-8")
    (out / f"{tool}.stderr").write_text(se, encoding="utf-8")
    meta = {"cmd": " ".join(cmd), "rc": rc, "seconds": round(dt, 2)}
    (out / f"{tool}.run.json").write_text(json.dumps(meta) + "\n", encoding="utf-8")
    return {**meta, "stdout": so, "stderr": se}


def load_run(tool: str, out: Path) -> dict[str, Any]:
    """A run already made (``--rejudge``): its status, time and console."""
    meta = json.loads((out / f"{tool}.run.json").read_text(encoding="utf-8"))
    return {**meta, "stdout": (out / f"{tool}.stdout").read_text(encoding="utf-8"),
            "stderr": (out / f"{tool}.stderr").read_text(encoding="utf-8")}


def judge(tool: str, run: dict[str, Any], truth: dict[str, Any], raw: dict[str, Any], out: Path) -> dict[str, Any]:
    checks: dict[str, dict[str, str]] = {}
    jpath = out / f"{tool}.json"
    doc: dict[str, Any] = {}
    jerr = None
    if jpath.is_file():
        try:
            doc = strict_load(jpath.read_text(encoding="utf-8"))
        except ValueError as exc:
            jerr = str(exc)
    else:
        jerr = "no JSON written"
    if run["rc"] != 0 or jerr:
        last = run["stderr"].strip().splitlines()[-1:] if run["stderr"].strip() else ""
        checks["exit"] = res(FAIL, f"exit {run['rc']}; {jerr or ''}; {last}")
    else:
        checks["exit"] = res(PASS)
    mdp = out / f"{tool}_report" / "report.md"
    md = mdp.read_text(encoding="utf-8") if mdp.is_file() else None
    console = run["stdout"]
    stem = Path(str(truth.get("csv", "x.csv"))).stem
    texts = [t.replace(stem, "RECORD") for t in strings(doc) + console.splitlines() + (md.splitlines() if md else [])]
    if not doc:
        for c in CHECKS[1:]:
            checks[c] = res(FAIL if c != "exit" else PASS, "no JSON to judge")
    else:
        checks["causal"] = check_causal(tool, doc)
        checks["cmd"] = check_cmd(tool, doc, truth)
        checks["phase"] = check_phase(tool, doc, truth)
        checks["rate"] = check_rate(tool, doc, truth, raw)
        checks["settle"] = check_settle(tool, doc, truth, raw)
        checks["model"] = check_model(tool, doc, md, console)
        checks["halves"] = check_halves(tool, doc)
        checks["undecid"] = check_undecided(tool, doc)
        checks["resol"] = check_resol(tool, doc, truth, raw)
        checks["lcycle"] = check_lcycle(truth, texts)
        checks["floor"] = check_floor(tool, doc, truth, texts)
        checks["drift"] = check_drift(tool, doc, truth, texts)
        checks["jitter"] = check_jitter(tool, doc, truth, texts)
        checks["corr"] = check_corr(doc)
        checks["sigma0"] = check_sigma0(tool, doc, console.splitlines() + (md.splitlines() if md else []))
        own = console.splitlines() + (md.splitlines() if md else [])
        checks["units"] = check_units(truth["unit"], strings(doc) + own)
        checks["channel"] = check_channel(tool, doc, texts)
    ratio = None
    if tool == "identify" and doc:
        ron = ((doc.get("final") or {}).get("rms_over_noise") or {})
        ratio = num(ron.get("position_deg")) if ron else None
    return {"checks": checks, "final_over_floor": ratio,
            "final_model": (doc.get("final") or {}).get("model") if tool == "identify" else None}


# ---------------------------------------------------------------------------------------------- main
def git_state() -> dict[str, str]:
    def g(*a: str) -> str:
        try:
            return subprocess.run(["git", "-C", str(ROOT), *a], capture_output=True, text=True, timeout=30,
                                  check=False).stdout.strip()
        except (OSError, subprocess.TimeoutExpired):
            return "?"
    return {"commit": g("rev-parse", "HEAD"), "status": "\n".join(g("status", "--short").splitlines()[:20])}


def main() -> int:  # noqa: PLR0915 - the script, top to bottom
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("heldout", "dev"), default="heldout")
    ap.add_argument("--out", default="/tmp/truthful")
    ap.add_argument("--cases", default=None, help="comma-separated case names (default: all)")
    ap.add_argument("--seeds", default=None, help="comma-separated seeds (default: the set's)")
    ap.add_argument("--tools", default="analyze,identify")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per tool run")
    ap.add_argument("--rejudge", action="store_true", help="judge the runs already in --out again, run nothing")
    args = ap.parse_args()
    out = Path(args.out)
    (out / "records").mkdir(parents=True, exist_ok=True)
    default = rigs.DEV_SEEDS if args.set == "dev" else rigs.HELDOUT_SEEDS
    seeds = [int(s) for s in args.seeds.split(",")] if args.seeds else list(default)
    if (args.set == "dev" and any(s >= 100 for s in seeds)) or (args.set == "heldout" and any(s < 100 for s in seeds)):
        ap.error("dev seeds are < 100, held-out seeds >= 100")
    names = args.cases.split(",") if args.cases else list(rigs.CASES)
    tools = args.tools.split(",")
    state = git_state()
    ran_s = None
    if args.rejudge and (out / "summary.json").is_file():
        before = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        state, ran_s = before["git"], before.get("elapsed_s")
    print(f"commit {state['commit']}\n{state['status']}\n", flush=True)
    t_start = time.monotonic()
    items = []
    for name in names:
        for seed in seeds:
            _, csv, tpath = rigs.generate(name, seed, out / "records")
            truth = json.loads(tpath.read_text(encoding="utf-8"))
            raw = raw_facts(read_record(csv))
            items.append((name, seed, csv, truth, raw))
    print(f"generated {len(items)} records in {time.monotonic() - t_start:.1f} s", flush=True)
    jobs = [(it, tool) for it in items for tool in tools]
    jobs.sort(key=lambda j: j[1] != "identify")  # the long ones first
    if args.rejudge:  # judge the runs that were made; a partial --out is not an error
        made = [j for j in jobs if (out / "runs" / f"{j[0][0]}_s{j[0][1]}" / f"{j[1]}.run.json").is_file()]
        if not made:
            ap.error(f"--rejudge: no runs in {out / 'runs'} for these cases, seeds and tools")
        if len(made) < len(jobs):
            print(f"rejudging the {len(made)} of {len(jobs)} runs that were made", flush=True)
        jobs = made

    def work(job: tuple[Any, str]) -> dict[str, Any]:
        (name, seed, csv, truth, raw), tool = job
        d = out / "runs" / f"{name}_s{seed}"
        run = load_run(tool, d) if args.rejudge else run_tool(tool, csv, truth, d, args.timeout)
        verdict = judge(tool, run, truth, raw, d)
        row = {"case": name, "seed": seed, "tool": tool, "seconds": run["seconds"], "rc": run["rc"], "cmd": run["cmd"],
               **verdict}
        fails = [c for c, v in verdict["checks"].items() if v["status"] == FAIL]
        print(f"  {name} s{seed} {tool}: {run['seconds']:.1f} s, fails: {', '.join(fails) or 'none'}", flush=True)
        return row

    rows: list[dict[str, Any]] = []
    with cf.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as ex:
        for row in ex.map(work, jobs):
            rows.append(row)
    rows.sort(key=lambda r: (names.index(r["case"]), r["seed"], r["tool"]))
    truths = {f"{n}_s{s}": {"truth": {k: v for k, v in t.items() if k != "drive"}, "numpy_on_record": raw}
              for n, s, _, t, raw in items}
    tally = {tool: {c: {PASS: 0, FAIL: 0, NA: 0} for c in CHECKS} for tool in tools}
    for r in rows:
        for c in CHECKS:
            tally[r["tool"]][c][r["checks"].get(c, {"status": NA})["status"]] += 1
    elapsed = ran_s if args.rejudge and ran_s is not None else round(time.monotonic() - t_start, 1)
    summary = {"set": args.set, "seeds": seeds, "git": state, "elapsed_s": elapsed, "rejudged": bool(args.rejudge),
               "tally": tally, "rows": rows, "records": truths}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    table = render(rows, tally, summary)
    (out / "summary.md").write_text(table, encoding="utf-8")
    print(table)
    return 0


ABBR = {PASS: "P", FAIL: "F", NA: "-"}


def render(rows: list[dict[str, Any]], tally: dict[str, Any], summary: dict[str, Any]) -> str:
    lines = [f"# truthful: {summary['set']} set, seeds {summary['seeds']}", "",
             f"commit `{summary['git']['commit']}`; elapsed {summary['elapsed_s']} s", "",
             "```", summary["git"]["status"] or "(clean)", "```", "",
             "P = PASS, F = FAIL, - = n.a.", "",
             "| case | seed | tool | " + " | ".join(CHECKS) + " | s | final/floor |",
             "| --- | --- | --- | " + " | ".join("---" for _ in CHECKS) + " | --- | --- |"]
    for r in rows:
        ratio = f"{r['final_over_floor']:.2f}" if r.get("final_over_floor") is not None else ""
        lines.append(f"| {r['case']} | {r['seed']} | {r['tool']} | "
                     + " | ".join(ABBR[r["checks"].get(c, {"status": NA})["status"]] for c in CHECKS)
                     + f" | {r['seconds']:.0f} | {ratio} |")
    lines += ["", "## Tally (PASS / FAIL / n.a.)", "", "| check | " + " | ".join(tally) + " |",
              "| --- | " + " | ".join("---" for _ in tally) + " |"]
    for c in CHECKS:
        cells = " | ".join(f"{t[c][PASS]} / {t[c][FAIL]} / {t[c][NA]}" for t in tally.values())
        lines.append(f"| {c} | {cells} |")
    lines += ["", "## Failures", ""]
    for r in rows:
        for c in CHECKS:
            v = r["checks"].get(c)
            if v and v["status"] == FAIL:
                lines.append(f"- **{r['case']} s{r['seed']} {r['tool']} {c}**: {v['why']}")
    times = [r["seconds"] for r in rows if r["tool"] == "identify"]
    ratios = [r["final_over_floor"] for r in rows if r.get("final_over_floor") is not None]
    if times:
        lines += ["", f"identify run time: median {np.median(times):.0f} s, max {max(times):.0f} s"]
    if ratios:
        q = np.percentile(ratios, [0, 25, 50, 75, 100])
        lines += [f"final/floor ratio: min {q[0]:.2f}, quartiles {q[1]:.2f} / {q[2]:.2f} / {q[3]:.2f}, max {q[4]:.2f}"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
