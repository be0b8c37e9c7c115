"""Ctrl-C stops a long solve promptly with KeyboardInterrupt (the C++ loop polls for signals)."""
import signal
import subprocess
import sys
import time

# The child installs Python's SIGINT handler itself: a shell that starts a job in
# the background (as CI harnesses may) makes it inherit SIGINT ignored.
SCRIPT = r"""
import signal, time, emu
signal.signal(signal.SIGINT, signal.default_int_handler)
s = emu.scenes.fusiform(3, warn=False)
solver = emu.Solver(s, "emu", step="woodbury", alpha=1e4, max_iterations=10**8, rtol_grad=1e-300,
                    rtol_energy=1e-300)
print("ready", flush=True)
t = time.time()
try:
    solver.solve({"belly": 5e4})
    print("finished")
except KeyboardInterrupt:
    print("interrupted %.3f" % (time.time() - t))
"""


def test_ctrl_c_interrupts_a_long_solve():
    p = subprocess.Popen([sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "ready"
        time.sleep(1.0)
        p.send_signal(signal.SIGINT)
        out, _ = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert out.startswith("interrupted"), out
    assert float(out.split()[1]) < 30.0
