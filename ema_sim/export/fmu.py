"""An FMI 2.0 co-simulation FMU of the exported C model: modelDescription.xml, the wrapper, the binary.

The FMU holds the C sources (:mod:`ema_sim.export.csource` and the FMI wrapper here, with the FMI
headers) and a binary built here with gcc, so a host needs no Python. Its variables:

* inputs ``command_deg`` and ``hinge_moment_inlb`` (positive aids positive deflection), read at each
  communication point and held over the step (``canInterpolateInputs`` false);
* outputs ``position_deg`` (the LVDT), ``surface_deg``, ``rate_dps`` and the limit ``flags``;
* every parameter of the model as a fixed parameter with its unit, range and description from its
  metadata (:mod:`ema_sim.parameters`), its start value the exported model's.

The step is the model's own (``DefaultExperiment stepSize``, ``canHandleVariableCommunicationStepSize``
false): ``fmi2DoStep`` with another step size, or at a time the model's steps have not reached,
returns ``fmi2Error`` and says why. Leaving initialization trims the model at rest under the inputs
then set.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from ema_sim import parameters as pm
from ema_sim.export import csource, harness, hoad_c, lti
from ema_sim.export.fmi_wrapper import (
    FLAGS_VR,
    HIGH_ORDER_OUTPUTS,
    INPUTS,
    OUTPUTS,
    PARAM_VR0,
    POWER_VR,
    SEED_VR,
    wrapper,
)
from ema_sim.export.target import ExportError, ExportTarget
from ema_sim.models.second_order.params import P, SecondOrderParams

FMI_HEADERS: tuple[str, ...] = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
WRAPPER_FILE = "ema_fmi2.c"
PLATFORM = "linux64"
MANIFEST = "ema_export.json"
"""The target's manifest, in the FMU's ``resources/``."""

UNITS: dict[str, str] = {
    "rad/s": '<BaseUnit s="-1" rad="1"/>',
    "deg": f'<BaseUnit rad="1" factor="{math.pi / 180.0!r}"/>',
    "deg/s": f'<BaseUnit s="-1" rad="1" factor="{math.pi / 180.0!r}"/>',
    "deg/s²": f'<BaseUnit s="-2" rad="1" factor="{math.pi / 180.0!r}"/>',
    "in": '<BaseUnit m="1" factor="0.0254"/>',
    "s": '<BaseUnit s="1"/>',
    "Hz": '<BaseUnit s="-1"/>',
    "in.lb": '<BaseUnit kg="1" m="2" s="-2" factor="0.1129848290276167"/>',
    "in·lb": '<BaseUnit kg="1" m="2" s="-2" factor="0.1129848290276167"/>',
    "in·lb·s²": '<BaseUnit kg="1" m="2" factor="0.1129848290276167"/>',
    "lbf/in": '<BaseUnit kg="1" s="-2" factor="175.12683524647639"/>',
}
"""SI base units of the units the variables carry (the others are declared without one)."""


def model_identifier(target: ExportTarget) -> str:
    """The FMU's model identifier (a C identifier: the binary's and the zip's stem).

    Parameters
    ----------
    target : ExportTarget
        What is exported.

    Returns
    -------
    str
        ``ema_<model>_<channel>``.
    """
    raw = f"ema_{target.model}_{target.channel}"
    return "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in raw)


def guid(target: ExportTarget) -> str:
    """A GUID that changes with anything the model computes (name, rate, method, parameter values).

    Parameters
    ----------
    target : ExportTarget
        What is exported.

    Returns
    -------
    str
        ``{xxxxxxxx-...}``.
    """
    key = f"{target.model}|{target.channel}|{target.rate_hz!r}|{target.backward}|" + ",".join(
        repr(float(v)) for v in target.kernel_vector())
    if target.options:
        key += "|" + ",".join(f"{k}={v!r}" for k, v in sorted(target.options.items()))
    return "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, "ema_sim:" + key)) + "}"


def _attr(x: float) -> str:
    if math.isinf(x):
        return "INF" if x > 0 else "-INF"
    return repr(float(x))


def _unit(unit: str) -> str | None:
    return None if unit in ("-", "") else unit


def _real(name: str, vr: int, causality: str, variability: str, description: str, *, unit: str | None = None,
          start: float | None = None, initial: str | None = None, lo: float | None = None,
          hi: float | None = None) -> str:
    attrs = [f"name={quoteattr(name)}", f'valueReference="{vr}"', f'causality="{causality}"',
             f'variability="{variability}"']
    if initial:
        attrs.append(f'initial="{initial}"')
    attrs.append(f"description={quoteattr(description)}")
    real = []
    if unit:
        real.append(f"unit={quoteattr(unit)}")
    if lo is not None and math.isfinite(lo):
        real.append(f'min="{_attr(lo)}"')
    if hi is not None and math.isfinite(hi):
        real.append(f'max="{_attr(hi)}"')
    if start is not None:
        real.append(f'start="{_attr(start)}"')
    return f'    <ScalarVariable {" ".join(attrs)}>\n      <Real {" ".join(real)}/>\n    </ScalarVariable>'


def parameter_range(name: str) -> tuple[float, float]:
    """A parameter's declared range with its switch-off value inside it (what a host may set).

    Parameters
    ----------
    name : str
        Parameter name.

    Returns
    -------
    tuple of float
        (min, max); infinite where unbounded (an infinite switch-off value leaves that side unbounded).
    """
    m = pm.metas(SecondOrderParams)[name]
    lo, hi = m.min, m.max
    if m.off is not None:
        lo, hi = min(lo, m.off), max(hi, m.off)
    return lo, hi


def _parameter_variables(target: ExportTarget, units: set[str]) -> list[str]:
    """The kernel's parameters as fixed FMU parameters (figure 26's or figure 30's slots), their units added."""
    if target.linear:
        return []
    vector = target.kernel_vector()
    out: list[str] = []
    if target.high_order:
        for slot, row in enumerate(hoad_c.slot_rows()):
            lo, hi = row.lo, row.hi
            if row.off is not None:
                lo, hi = min(lo, row.off), max(hi, row.off)
            punit = _unit(row.unit)
            if punit:
                units.add(punit)
            low = "(" if row.lo_exclusive else "["
            off = f"; {row.off:g} switches it off" if row.off is not None else ""
            out.append(_real(row.name, PARAM_VR0 + slot, "parameter", "fixed",
                             f"{row.description}; range {low}{row.lo:g}, {row.hi:g}] {row.unit}{off}",
                             unit=punit, start=float(vector[slot]), initial="exact", lo=lo, hi=hi))
        return out
    for name, m in pm.metas(SecondOrderParams).items():
        if m.kernel is None:
            continue
        slot = getattr(P, m.kernel)
        lo, hi = parameter_range(name)
        punit = _unit(m.unit)
        if punit:
            units.add(punit)
        off = f"; {m.off:g} switches it off" if m.off is not None else ""
        out.append(_real(m.kernel, PARAM_VR0 + slot, "parameter", "fixed",
                         f"{m.description}; range {m.range_text()}{off}", unit=punit, start=float(vector[slot]),
                         initial="exact", lo=lo, hi=hi))
    return out


def model_description(target: ExportTarget) -> str:
    """``modelDescription.xml``.

    Parameters
    ----------
    target : ExportTarget
        What is exported.

    Returns
    -------
    str
        The XML text.
    """
    ident = model_identifier(target)
    variables: list[str] = []
    output_index: list[int] = []
    units: set[str] = set()
    # a high-order model's inputs are discrete (held from one communication point to the next): a host (FMPy) then
    # feeds each frame the value logged for it, never one interpolated between two frames at a rounded time
    variability = "discrete" if target.high_order else "continuous"
    for i, (name, unit, desc) in enumerate(INPUTS):
        variables.append(_real(name, i, "input", variability, desc, unit=unit, start=0.0))
        units.add(unit)
    if target.high_order:
        variables.append(_real("motor_power", POWER_VR, "input", "discrete", "motor power: 1 on, 0 off (the bridge "
                               "opens, the brake holds, the bus reads 0 V), held over the step", start=1.0))
    for j, (name, unit, _, desc) in enumerate(OUTPUTS):
        variables.append(_real(name, 2 + j, "output", "discrete", desc, unit=unit, initial="calculated"))
        output_index.append(len(variables))
        units.add(unit)
    flag_text = ("limit flags: 1 rate, 2 position, 4 free play, 16 current, 32 PWM dead band, 64 brake, 128 stall"
                 if target.high_order else "limit flags: 1 rate, 2 position, 4 free-play stop, 8 threshold, 16 current")
    variables.append(f'    <ScalarVariable name="flags" valueReference="{FLAGS_VR}" causality="output" '
                     f'variability="discrete" initial="calculated" description="{flag_text}">\n      <Integer/>\n'
                     '    </ScalarVariable>')
    output_index.append(len(variables))
    if target.high_order:
        for name, unit, vr, desc in HIGH_ORDER_OUTPUTS:
            variables.append(_real(name, vr, "output", "discrete", desc, unit=unit, initial="calculated"))
            output_index.append(len(variables))
            units.add(unit)
        seed = int(target.options.get("seed", 0.0))
        variables.append(f'    <ScalarVariable name="noise_seed" valueReference="{SEED_VR}" causality="parameter" '
                         'variability="fixed" initial="exact" description="the noise seed (the stream of ema_sim\'s '
                         f'generator; the model\'s seed= option)">\n      <Integer start="{seed}"/>\n'
                         '    </ScalarVariable>')
    if target.linear:
        for slot, (name, unit, desc, value) in enumerate(lti.parameter_rows(target)):
            units.add(unit)
            variables.append(_real(name, PARAM_VR0 + slot, "parameter", "fixed", desc, unit=unit, start=value,
                                   initial="exact", lo=value, hi=value))
    variables.extend(_parameter_variables(target, units))
    outputs = "".join(f'      <Unknown index="{k}"/>\n' for k in output_index)
    unit_defs = "".join(
        f"    <Unit name={quoteattr(u)}>{UNITS.get(u, '')}</Unit>\n" for u in sorted(units))
    sources = "".join(f'      <File name="{f}"/>\n' for f in (*harness.sources(target), WRAPPER_FILE))
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(ident)} guid="{guid(target)}"\n'
        f"  description={quoteattr(target.description)}\n"
        f'  generationTool="ema_sim (ema export)" variableNamingConvention="flat" numberOfEventIndicators="0">\n'
        f'  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="false"\n'
        '    canInterpolateInputs="false" canBeInstantiatedOnlyOncePerProcess="false"\n'
        '    canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="false" canSerializeFMUstate="false"\n'
        '    providesDirectionalDerivative="false">\n'
        f"    <SourceFiles>\n{sources}    </SourceFiles>\n"
        "  </CoSimulation>\n"
        f"  <UnitDefinitions>\n{unit_defs}  </UnitDefinitions>\n"
        "  <LogCategories>\n    <Category name=\"logStatusError\"/>\n  </LogCategories>\n"
        f'  <DefaultExperiment startTime="0.0" stepSize="{1.0 / target.rate_hz!r}"/>\n'
        "  <ModelVariables>\n" + "\n".join(variables) + "\n  </ModelVariables>\n"
        "  <ModelStructure>\n"
        f"    <Outputs>\n{outputs}    </Outputs>\n"
        f"    <InitialUnknowns>\n{outputs}    </InitialUnknowns>\n"
        "  </ModelStructure>\n"
        "</fmiModelDescription>\n"
    )


def fmi_headers() -> Path:
    """The directory holding the FMI 2.0 headers (FMPy's copy of the standard's).

    Returns
    -------
    pathlib.Path
        The directory.
    """
    try:
        import fmpy  # type: ignore[import-untyped]  # noqa: PLC0415 - FMPy: a test tool, only to verify an FMU
    except ImportError:
        raise ExportError("building an FMU needs fmpy for the FMI 2.0 headers: pip install fmpy==0.3.32") from None
    where = Path(fmpy.__file__).parent / "c-code"
    if not all((where / h).is_file() for h in FMI_HEADERS):
        raise ExportError(f"the FMI 2.0 headers are not in {where}")
    return where


def build_fmu(target: ExportTarget, out: Path) -> Path:
    """Write the FMU: sources, a binary for this platform built with gcc, modelDescription.xml.

    Parameters
    ----------
    target : ExportTarget
        What is exported.
    out : pathlib.Path
        The ``.fmu`` file.

    Returns
    -------
    pathlib.Path
        ``out``.
    """
    ident = model_identifier(target)
    headers = fmi_headers()
    with tempfile.TemporaryDirectory(prefix="ema_fmu_") as tmp:
        root = Path(tmp)
        src = root / "sources"
        harness.model_sources(src, target)
        (src / WRAPPER_FILE).write_text(wrapper(), encoding="utf-8")
        for h in FMI_HEADERS:
            shutil.copy(headers / h, src / h)
        binary = root / "binaries" / PLATFORM / f"{ident}.so"
        binary.parent.mkdir(parents=True)
        csource.compile_c([src / f for f in (*harness.sources(target), WRAPPER_FILE)], binary, shared=True,
                          include=[src], defines=[f'EMA_GUID="{guid(target)}"'])
        (root / "modelDescription.xml").write_text(model_description(target), encoding="utf-8")
        (src / "README.txt").write_text(build_note(target), encoding="utf-8")
        resources = root / "resources"
        resources.mkdir()
        (resources / MANIFEST).write_text(json.dumps(target.manifest("fmu"), indent=2) + "\n", encoding="utf-8")
        out.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(root.rglob("*")):
                if path.is_file():
                    zf.write(path, path.relative_to(root).as_posix())
    return out


def build_note(target: ExportTarget) -> str:
    """How to rebuild the binary from the FMU's sources (the flags that keep it bit for bit).

    Parameters
    ----------
    target : ExportTarget
        What is exported.

    Returns
    -------
    str
        A short text.
    """
    files = " ".join((*harness.sources(target), WRAPPER_FILE))
    return (f"{escape(target.description)}\n\nRebuild the binary (the flags keep its arithmetic the model's):\n"
            f"  gcc {' '.join(csource.CFLAGS)} -fPIC -shared -DEMA_GUID='\"{guid(target)}\"' "
            f"-o {model_identifier(target)}.so {files} -lm\n")


def validation_problems(path: Path) -> list[str]:
    """FMPy's validation of an FMU (its modelDescription.xml against the schema and the standard's rules).

    Parameters
    ----------
    path : pathlib.Path
        The ``.fmu``.

    Returns
    -------
    list of str
        The problems found (empty: clean).
    """
    from fmpy.validation import validate_fmu  # type: ignore[import-untyped]  # noqa: PLC0415 - FMPy: a test tool, only to verify an FMU

    problems: list[str] = validate_fmu(str(path))
    return problems
