"""The actuator in other simulators: export a model and verify the artefact against the truth.

* :mod:`.target`       what is exported: the model, its values, rate and method, the truth, the manifest
* :mod:`.cstages`      figure 26's stages in C, each beside the numba function it transcribes
* :mod:`.csource`      the C model: header, kernel, the model's values; gcc
* :mod:`.fmu`          the FMI 2.0 co-simulation FMU: modelDescription.xml, the wrapper, the binary
* :mod:`.jsbsim_system` the JSBSim ``<system>`` of flight-control components, and running it in JSBSim
* :mod:`.harness`      the plain C export with its harness program, and running the harness
* :mod:`.artefacts`    an artefact opened from disk and stepped (FMPy, JSBSim, the harness)
* :mod:`.verify`       ``ema verify``: the artefact against the truth, the sign and unit check
* :mod:`.diagnose`     a host's recorded integration against the truth, its likely fault named

The CLI is :mod:`ema_sim.commands.export` (``ema export``, ``ema verify``); the page is ``docs/export.md``.
"""
