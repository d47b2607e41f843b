"""The tests' one wall-clock limit: what a hung process, flight or wait gets before its test fails.

Never a speed check: a test that waits for something (a subprocess, a message, a flight) waits up to this
long, which no working run reaches on a loaded 2-core machine (a first run that compiles the kernels takes
about a minute there); only a hang does. Speed is measured by bench/, not asserted by the tests.
"""

HANG_TIMEOUT_S = 30 * 60.0   #: [s, wall]
