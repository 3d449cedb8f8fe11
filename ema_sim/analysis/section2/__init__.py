"""The section-2 tests of the report, one module each, run on records by ``ema analyze``.

``base`` says what a test is (:class:`~ema_sim.analysis.section2.base.base.Section2Test`) and the record it
runs on; ``segments`` what the recogniser hands a test to read. The tests, in report order (the
registry's): ``steps``, ``timing``, ``frequency_response``, ``cycles``, ``sine_dwell``, ``moves``,
``calibration_fit``, ``threshold`` (static and dynamic), ``crosstalk``, ``dither``, ``compliance``,
``hysteresis``, ``free_play``, ``regeneration``.
"""
