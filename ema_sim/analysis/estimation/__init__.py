"""What is measured from signals, shared by every section-2 test and by ``ema identify``.

Spectra and frequency responses (``spectra``, ``frf``, ``harmonics``), tone fits (``sine_fit``),
transfer-function and second-order fits (``tf_fit``, ``second_order_fit``) with their coloured-residual
uncertainty (``uncertainty``), the noise floor and residual tests (``noise``, on the count ``grid``),
readouts of a response (``settling``, ``slew``), and the one-word ``quality`` every result carries.
``prepared`` reads a record's columns once and measures what ``ema analyze`` and ``ema identify`` both start
from (channel, noise, command timing, slew, stamps, saturation, travel, units).
"""
