"""What the tests of the benchmark's frame scripts (bench/outline_error.py,
bench/shift_error.py) share: the renders' background and running a script on
a folder of frames."""
import json, os, subprocess, sys

import numpy as np

BG = np.array([0.16, 0.17, 0.20])


def run(script, folder, *extra):
    """Runs `script` on `folder`; returns the process and, when it succeeded, its JSON."""
    out = os.path.join(folder, "r.json")
    p = subprocess.run([sys.executable, script, folder, "--json", out, *extra], capture_output=True, text=True)
    return p, (json.load(open(out)) if p.returncode == 0 else None)
