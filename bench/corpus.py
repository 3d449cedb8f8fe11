"""``ema identify`` over a corpus of generated records: exit codes, final/floor and run-time distributions.

The corpora are the fuzz records (``test/fuzzgen.py``, the corpus identification is developed against)
and the strangers (``test/strangers.py``, held out: evaluated, never developed on). Each record is run
through the command line as a user runs it (default search, one worker per run, ``--jobs`` runs at a
time), and the figures of ``docs/identify-unnamed.md``'s results table are printed:

- exit codes, and whether the JSON is strict;
- final / baseline and final / reference, the largest over outputs and records (never above 1);
- final / floor quartiles and p90 (the first output's);
- run time median / p90 / max.

    python bench/corpus.py --set strangers --seeds 0-29 [--length short|long|mixed] --jobs 2 --out /tmp/corpus
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
import fuzzgen  # noqa: E402
import strangers  # noqa: E402

EMA = ROOT / ".venv" / "bin" / "ema"


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def _write(corpus: str, seed: int, folder: Path, length: str) -> tuple[Path, list[str]]:
    """One record's CSV and the options it needs (a stranger's stamps are ``time_ms``)."""
    short = length == "short" or (length == "mixed" and seed % 2 == 0)
    if corpus == "fuzz":
        _, cols = fuzzgen.record(seed, short=short)
        return fuzzgen.write(cols, folder / f"fuzz{seed}.csv"), []
    _, cols = strangers.record(seed, short=short)
    names = ",".join(f"{k}={k}" for k in cols)
    return strangers.write(cols, folder / f"stranger{seed}.csv"), ["--columns", names]


def _run(csv: Path, extra: list[str], out: Path, timeout: float) -> dict[str, Any]:
    js = out / f"{csv.stem}.json"
    cmd = [str(EMA), "identify", str(csv), "--json", str(js), "-q", "--workers", "1", *extra]
    env = dict(os.environ, NUMBA_NUM_THREADS="1", MPLBACKEND="Agg")
    t0 = time.monotonic()
    try:
        rc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, check=False).returncode
    except subprocess.TimeoutExpired:
        rc = -9
    row: dict[str, Any] = {"record": csv.stem, "rc": rc, "seconds": round(time.monotonic() - t0, 2)}
    if rc != 0 or not js.is_file():
        return row
    try:
        doc = json.loads(js.read_text(encoding="utf-8"),
                         parse_constant=lambda c: (_ for _ in ()).throw(ValueError(f"non-strict JSON {c}")))
    except ValueError as exc:
        row["strict"] = str(exc)
        return row
    final, noise = doc["final"]["rms_deg"], doc["noise_deg"]
    first = next(iter(final))
    row.update(strict=True, final_over_floor=final[first] / noise[first],
               final_over_baseline=max(final[o] / max(doc["baseline"]["rms_deg"][o], 1e-300) for o in final),
               final_over_reference=max(final[o] / max(doc["reference"]["rms_deg"][o], 1e-300) for o in final),
               model=doc["final"].get("model"))
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("fuzz", "strangers"), default="strangers")
    ap.add_argument("--seeds", default="0-29")
    ap.add_argument("--length", choices=("short", "long", "mixed"), default="short",
                    help="the generators' short (seconds) or long (tens of seconds) records, or every other one")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--out", default="/tmp/corpus")
    args = ap.parse_args()
    out = Path(args.out) / args.set
    out.mkdir(parents=True, exist_ok=True)
    items = [_write(args.set, s, out, args.length) for s in _seeds(args.seeds)]
    with cf.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as ex:
        rows = list(ex.map(lambda it: _run(it[0], it[1], out, args.timeout), items))
    ok = [r for r in rows if r.get("strict") is True]
    ratio = np.array([r["final_over_floor"] for r in ok])
    secs = np.array([r["seconds"] for r in rows])
    codes: dict[int, int] = {}
    for r in rows:
        codes[r["rc"]] = codes.get(r["rc"], 0) + 1
    summary = {
        "set": args.set, "seeds": args.seeds, "length": args.length, "records": len(rows),
        "exit_codes": {str(k): v for k, v in sorted(codes.items())},
        "strict_json": len(ok),
        "final_over_baseline_max": max((r["final_over_baseline"] for r in ok), default=None),
        "final_over_reference_max": max((r["final_over_reference"] for r in ok), default=None),
        "final_over_floor_p25_p50_p75_p90": [float(np.percentile(ratio, q)) for q in (25, 50, 75, 90)]
        if ratio.size else None,
        "seconds_median_p90_max": [float(np.median(secs)), float(np.percentile(secs, 90)), float(secs.max())],
        "rows": rows,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
