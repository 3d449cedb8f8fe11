"""Studies run on the models rather than on records: acceptance tests, rw13 hysteresis, the LOES, table 6.

``acceptance`` (table 1 and A2), ``hysteresis_study`` (rw13 and figure 37 on HOAD3), ``loes`` (the
low-order equivalent system of section 3.4), ``model_error`` (table 6 and figure 40).
"""
