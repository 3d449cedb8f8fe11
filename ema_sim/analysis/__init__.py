"""Offline analysis of records: the report's test results (``ema analyze``) and model-to-model errors.

``pipeline`` runs a record through ``recognize`` (which section-2 tests it holds) and the analyses:
``frequency_response`` (on ``spectra``), ``second_order_fit`` (with ``uncertainty``), ``steps`` and
``timing``, ``calibration_fit``, ``compliance``, ``hysteresis``, ``free_play``, ``threshold``,
``crosstalk``, ``dither``, ``regeneration``; ``report`` and ``plots`` write the JSON, Markdown and PNGs.
``noise`` (noise floor, whiteness, input independence) and ``uncertainty`` serve model identification
too. ``model_error`` compares discrete models with their continuous reference (table 6).
"""
