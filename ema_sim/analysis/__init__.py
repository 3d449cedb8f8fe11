"""Offline analysis of records: the report's test results (``ema analyze``) and studies on the models.

Grouped so that each group imports only the groups before it (``test/test_analysis_layout.py``):

* ``records``: loading a record, time-series helpers, periodic cycles, held or sampled command;
* ``estimation``: spectra and frequency responses, sine, transfer-function and second-order fits with
  their uncertainty, the noise floor and residual tests, readouts of a response, result quality;
* ``formatting``: what every test's figures and Markdown share;
* ``section2``: the section-2 tests, one module each, their interface (``base``) and what they read
  (``segments``);
* ``registry``, ``recognize``, ``pipeline``, ``report``, ``plots`` (this package): ``ema analyze``
  recognising a record's tests, running them and writing the JSON, Markdown and PNGs;
* ``studies``: acceptance tests, the rw13 hysteresis study, the LOES and model-to-model errors
  (table 6), run on the models.

``estimation.noise`` and ``estimation.uncertainty`` serve model identification too.
"""
