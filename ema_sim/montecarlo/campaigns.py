"""A campaign end to end: found by name or file, run on Dask, summarised, plotted, its findings checked."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from ema_sim.errors import ConfigError
from ema_sim.montecarlo import output, plots
from ema_sim.montecarlo.builtin import BUILTIN, builtin_campaign, findings
from ema_sim.montecarlo.campaign import Campaign, analysis_spread, parse_campaign, read_campaign
from ema_sim.montecarlo.engine import run_tasks
from ema_sim.montecarlo.summary import Summary, merged_envelopes, summarize


def load_campaign(name_or_path: str, *, channel: str | None = None, analysis: Sequence[str | Path] = ()) -> Campaign:
    """A built-in campaign by name or a campaign YAML file.

    Parameters
    ----------
    name_or_path : str
        A name of :data:`~ema_sim.montecarlo.builtin.BUILTIN` or a path.
    channel : str, optional
        The channel of a built-in campaign (default left_wing); overrides a file's.
    analysis : sequence of path
        ``ema analyze`` JSON files whose spread bounds the dispersions (``uniform: analysis``).

    Returns
    -------
    Campaign
        The campaign.
    """
    spread = analysis_spread(analysis) if analysis else None
    if name_or_path in BUILTIN:
        raw = builtin_campaign(name_or_path, channel or "left_wing", spread)
        return parse_campaign(raw, name_or_path, spread)
    path = Path(name_or_path)
    if path.suffix.lower() not in (".yaml", ".yml") and not path.exists():
        known = ", ".join(sorted(BUILTIN))
        raise ConfigError(f"unknown campaign {name_or_path!r}: not a built-in one ({known}) nor a YAML file")
    c = read_campaign(path, spread)
    if channel is not None and channel != c.channel:
        raw = dict(c.raw)
        raw["channel"] = channel
        c = parse_campaign(raw, str(path), spread)
    return c


def run_campaign(c: Campaign, out: str | Path, *, runs: int, seed: int, scheduler: str | None = None,
                 workers: int | None = None, resume: bool = False, plot: bool = True,
                 progress: Callable[[float], None] | None = None) -> Summary:
    """Run a campaign into ``out``: rows, summary, plots and (built-in campaigns) findings.

    Parameters
    ----------
    c : Campaign
        The campaign.
    out : str or pathlib.Path
        Its directory.
    runs : int
        Number of runs.
    seed : int
        The seed.
    scheduler : str, optional
        A Dask scheduler's address (default: a local cluster, one worker per core).
    workers : int, optional
        Worker processes of the local cluster.
    resume : bool
        Complete the campaign ``out`` holds.
    plot : bool
        Write the PNG plots.
    progress : callable, optional
        Called with the fraction of runs done.

    Returns
    -------
    dict
        The summary (also ``out/summary.json``).
    """
    out = Path(out)
    engine = run_tasks(c, out, runs=runs, seed=seed, scheduler=scheduler, workers=workers, resume=resume,
                       progress=progress)
    found = findings(c, out)
    pngs: list[str] = []
    doc = summarize(out, c, seed=seed, runs=runs, engine=engine, findings=found)
    if plot:
        envelopes, nominal, _, _, _ = merged_envelopes(out)
        for name, env in envelopes.items():
            path = out / f"envelope_{name.replace('.', '_')}.png"
            plots.envelope_plot(f"{c.name}: {name}", env, path)
            pngs.append(path.name)
        metrics = list(doc["metrics"])
        if plots.histograms(out, metrics, nominal, out / "histograms.png"):
            pngs.append("histograms.png")
        shown = [m for m in metrics if not m.endswith((".dither", ".peak_db", ".freq_hz"))][:6]
        if plots.sensitivity(out, list(c.parameters), shown, doc["sensitivity_spearman"], out / "sensitivity.png"):
            pngs.append("sensitivity.png")
        doc["plots"] = pngs
    output.write_summary(out, doc)
    return doc
