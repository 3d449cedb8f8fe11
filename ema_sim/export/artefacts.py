"""An exported artefact opened from disk and run one step per input.

The FMU runs with FMPy, the JSBSim system in JSBSim, the C export through its compiled harness.

Every artefact carries its manifest (:meth:`ema_sim.export.target.ExportTarget.manifest`): the FMU in
``resources/ema_export.json``, the C directory in ``ema_export.json``, the system file in a comment.
:func:`open_artefact` reads it back, so the truth ``ema verify`` compares against is rebuilt from the
artefact alone.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
import zipfile
from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np

from ema_sim.export import fmu as fmu_mod
from ema_sim.export import harness, jsbsim_system
from ema_sim.export.target import ExportError, ExportTarget, from_manifest
from ema_sim.models.arrays import FloatArray

OUTPUT_NAMES: tuple[str, ...] = ("position_deg", "surface_deg", "rate_dps")
"""The outputs every artefact gives and ``ema verify`` compares."""


class Artefact(ABC):
    """An exported model that steps once per input at its rate.

    Parameters
    ----------
    path : pathlib.Path
        Where it is.
    target : ExportTarget
        What its manifest says it is.
    """

    kind: str = ""

    def __init__(self, path: Path, target: ExportTarget) -> None:
        self.path = path
        self.target = target
        self.seconds = 0.0
        """Wall time of the last :meth:`run`'s stepping."""
        self.not_expressed: list[str] = []
        """Stages of the target the artefact leaves out (a JSBSim system's)."""

    @property
    def rate_hz(self) -> float:
        """The rate it is driven at, one input per frame (the model's own; a high-order model's frame of steps)."""
        return self.target.frame_hz

    @abstractmethod
    def run(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> dict[str, FloatArray]:
        """Trim at the first inputs, step once per input, read the outputs at every step boundary.

        Parameters
        ----------
        command_deg : numpy.ndarray
            Command per step (deg).
        hinge_moment_inlb : numpy.ndarray
            Hinge moment per step (in·lb, positive aids positive deflection).

        Returns
        -------
        dict
            :data:`OUTPUT_NAMES` → inputs + 1 values, time 0 first.
        """

    def close(self) -> None:  # noqa: B027 - most artefacts hold nothing
        """Release what it holds (temporary files)."""


class FmuArtefact(Artefact):
    """An FMU run by FMPy's ``simulate_fmu`` at its default step.

    Parameters
    ----------
    path : pathlib.Path
        The ``.fmu``.
    target : ExportTarget
        Its manifest.
    """

    kind = "fmu"

    def run(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> dict[str, FloatArray]:  # noqa: D102
        from fmpy import simulate_fmu  # type: ignore[import-untyped]  # noqa: PLC0415 - FMPy: a test tool, only to verify an FMU

        if self.target.high_order:
            return self._run_frames(command_deg, hinge_moment_inlb)
        n = command_deg.size
        dt = 1.0 / self.rate_hz
        signals = np.zeros(n, dtype=[("time", float), ("command_deg", float), ("hinge_moment_inlb", float)])
        signals["time"] = np.arange(n) * dt
        signals["command_deg"] = command_deg
        signals["hinge_moment_inlb"] = hinge_moment_inlb
        t0 = time.perf_counter()
        result = simulate_fmu(str(self.path), start_time=0.0, stop_time=n * dt, output_interval=dt, input=signals,
                              output=list(OUTPUT_NAMES), validate=False)
        self.seconds = time.perf_counter() - t0
        if result.size != n + 1:
            raise ExportError(f"{self.path}: FMPy returned {result.size} samples for {n} steps")
        return {k: np.asarray(result[k], dtype=float) for k in OUTPUT_NAMES}

    def _run_frames(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> dict[str, FloatArray]:
        """Drive the FMU through FMPy's FMI 2.0 calls, one ``fmi2DoStep`` per frame (as a host does).

        FMPy's ``simulate_fmu`` gives the same outputs; calling the FMU directly spares its per-step input
        search over a long record.
        """
        from fmpy import extract, read_model_description  # noqa: PLC0415 - FMPy: a test tool, only to verify an FMU
        from fmpy.fmi2 import FMU2Slave  # type: ignore[import-untyped]  # noqa: PLC0415 - FMPy: a test tool, only to verify an FMU

        md = read_model_description(str(self.path))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        unzipped = extract(str(self.path))
        slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName="ema_verify")
        n = command_deg.size
        dt = 1.0 / self.rate_hz
        inputs = [vr["command_deg"], vr["hinge_moment_inlb"]]
        outputs = [vr[o] for o in OUTPUT_NAMES]
        out = np.empty((n + 1, len(outputs)))
        t0 = time.perf_counter()
        try:
            slave.instantiate()
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            slave.setReal(inputs, [float(command_deg[0]), float(hinge_moment_inlb[0])])
            slave.exitInitializationMode()
            out[0] = slave.getReal(outputs)
            for k in range(n):
                slave.setReal(inputs, [float(command_deg[k]), float(hinge_moment_inlb[k])])
                slave.doStep(currentCommunicationPoint=k * dt, communicationStepSize=dt)
                out[k + 1] = slave.getReal(outputs)
            slave.terminate()
        finally:
            slave.freeInstance()
            shutil.rmtree(unzipped, ignore_errors=True)
        self.seconds = time.perf_counter() - t0
        return {o: out[:, j] for j, o in enumerate(OUTPUT_NAMES)}


class CArtefact(Artefact):
    """A C export directory, its harness compiled on first use.

    Parameters
    ----------
    path : pathlib.Path
        The directory.
    target : ExportTarget
        Its manifest.
    """

    kind = "c"

    def __init__(self, path: Path, target: ExportTarget) -> None:
        super().__init__(path, target)
        self._tmp = tempfile.TemporaryDirectory(prefix="ema_harness_")
        self.exe = harness.build_harness(path, Path(self._tmp.name) / harness.HARNESS_EXE)

    def run(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> dict[str, FloatArray]:  # noqa: D102
        t0 = time.perf_counter()
        frame = ("--frame", str(self.target.steps_per_frame)) if self.target.high_order else ()
        out = harness.run_harness(self.exe, command_deg, hinge_moment_inlb, frame)
        self.seconds = time.perf_counter() - t0
        return {k: out[k] for k in OUTPUT_NAMES}

    def close(self) -> None:  # noqa: D102
        self._tmp.cleanup()


class JsbsimArtefact(Artefact):
    """A JSBSim system file, hosted in a bare airframe and stepped at its rate.

    Parameters
    ----------
    path : pathlib.Path
        The system file.
    target : ExportTarget
        Its manifest.
    delay_frames : int
        The frames its delay line holds (filled before the record).
    """

    kind = "jsbsim"

    def __init__(self, path: Path, target: ExportTarget, delay_frames: int = 0) -> None:
        super().__init__(path, target)
        self.delay_frames = delay_frames
        self._runner = jsbsim_system.JsbsimRunner(path, target.rate_hz)

    def run(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> dict[str, FloatArray]:  # noqa: D102
        params = jsbsim_system.expressed_params(self.target.params)
        out, self.seconds = self._runner.run(params, command_deg, hinge_moment_inlb, self.delay_frames)
        return out

    def close(self) -> None:  # noqa: D102
        self._runner.close()


def _fmu_manifest(path: Path) -> dict[str, object]:
    try:
        with zipfile.ZipFile(path) as zf:
            doc: dict[str, object] = json.loads(zf.read(f"resources/{fmu_mod.MANIFEST}"))
            return doc
    except KeyError:
        raise ExportError(f"{path} carries no ema_sim manifest (not written by `ema export --fmu`)") from None
    except (OSError, zipfile.BadZipFile, ValueError) as exc:
        raise ExportError(f"{path}: not a readable FMU ({exc})") from None


def open_artefact(path: Path) -> Artefact:
    """Open an artefact ``ema export`` wrote: ``.fmu``, a JSBSim system ``.xml``, or a C directory.

    Parameters
    ----------
    path : pathlib.Path
        The artefact.

    Returns
    -------
    Artefact
        Ready to run.
    """
    if not path.exists():
        raise ExportError(f"{path}: no such file or directory")
    if path.is_dir():
        manifest = path / harness.MANIFEST
        if not manifest.is_file():
            raise ExportError(f"{path} is not an `ema export --c` directory (no {harness.MANIFEST})")
        return CArtefact(path, from_manifest(json.loads(manifest.read_text(encoding="utf-8"))))
    suffix = path.suffix.lower()
    if suffix == ".fmu":
        return FmuArtefact(path, from_manifest(_fmu_manifest(path)))
    if suffix == ".xml":
        doc = jsbsim_system.read_manifest(path)
        frames = doc.get("delay_frames", 0)
        art = JsbsimArtefact(path, from_manifest(doc), int(frames) if isinstance(frames, int | float) else 0)
        dropped = doc.get("not_expressed", [])
        art.not_expressed = [str(s) for s in dropped] if isinstance(dropped, list) else []
        return art
    raise ExportError(f"{path}: not an artefact ema verify runs (.fmu, a JSBSim .xml system, or a C directory; "
                      "a host's own record is a .csv or a bag)")


def steps_per_second(steps: int, seconds: float) -> float:
    """Steps per wall-clock second (infinite for no time).

    Parameters
    ----------
    steps : int
        Steps taken.
    seconds : float
        Wall time.

    Returns
    -------
    float
        Steps/s.
    """
    return steps / seconds if seconds > 0.0 else math.inf
