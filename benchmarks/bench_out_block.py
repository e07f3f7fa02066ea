"""``Monitor.run``'s CPU time against the output block of the compiled batch loop
(``grfguard.kernels.monitor.OUT_BLOCK``, rows per block of the column-major output; 1 =
one value per column and row, as before blocks), all sizes alternated in one process.

SURALP, the paper scenario on the 60 s walk (seed 0), default monitor::

    taskset -c 0 .venv/bin/python benchmarks/bench_out_block.py --rounds 11 --blocks 1,64,256,1024

Prints the minimum and median process CPU time per sample of each block size; the
outputs of every size are checked equal to the first's (`DataFrame.equals`, first round).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main() -> None:
    from grfguard.detect import Monitor
    from grfguard.faults import inject_faults
    from grfguard.kernels import monitor as km
    from grfguard.kernels import warm_up
    from grfguard.model.robot import SURALP
    from grfguard.sim import GaitConfig, NoiseConfig, simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--blocks", default="1,64,256,1024", help="comma-separated block sizes")
    a = ap.parse_args()
    blocks = [int(b) for b in a.blocks.split(",")]
    warm_up()
    walk = simulate(SURALP, GaitConfig(duration=60.0), NoiseConfig(), seed=0)
    raw = inject_faults(walk, ["r1=frozen:0@5", "r2=offset:100@5", "r3=drift:15@5",
                               "r4=offset:-100@5"], seed=0)
    mon = Monitor.for_log(raw)
    n = len(raw)
    ref = None
    res: dict[int, list[float]] = {b: [] for b in blocks}
    for r in range(a.rounds):
        for b in (blocks if r % 2 == 0 else blocks[::-1]):
            km.OUT_BLOCK = b
            c0 = time.process_time()
            out = mon.run(raw)
            res[b].append((time.process_time() - c0) / n * 1e6)
            if ref is None:
                ref = out
            elif r == 0 and not ref.equals(out):
                raise SystemExit(f"block {b}: output differs")
    for b in blocks:
        v = np.array(res[b])
        print(f"block {b:5d}: Monitor.run min {v.min():.3f} median {np.median(v):.3f} "
              f"µs/sample CPU")
    print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
