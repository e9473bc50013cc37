#!/bin/bash
# seed 9 runner: $1 = ids half, $2 = r1|r2. Code: /work/wt9d (e85aa5d + resume store, = 173f511's diff)
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=/work/wt9d
cd /work/wt9d
exec /work/main/.venv/bin/python benchmarks/bench_diagnose.py --cases /work/runs/concealedS9 --out /work/runs/diagnoseS9c \
   --workers 1 --continuation --ids "$1" --resume-store /work/runs/storeS9 >> /work/runs/diagnoseS9c_$2.log 2>&1
