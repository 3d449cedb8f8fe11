"""Aircraft-in-the-loop (AIL) harness (sections 2.10, 4.1, 4.3): vehicle, flight computer, loop.

A minimal rigid-body vehicle (:mod:`.vehicle`) flown by an attitude-hold autopilot (:mod:`.autopilot`),
both illustrative (``config/ail_vehicle.yaml``), close the loop through the actuator models and the
test environment (:mod:`ema_sim.environment`) in both directions. :mod:`.fmu` is one frame of the
flight computer and its vehicle simulation, shared by the ``fmu`` node and the offline loop
(:mod:`.loop`, ``ema ail``); :mod:`.measure` turns a run into the dither finding with
:mod:`ema_sim.analysis.section2.dither`.
"""
