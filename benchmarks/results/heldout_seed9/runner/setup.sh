#!/bin/bash
# Seed 9 on a machine that lacks /work/runs or the runner's worktree (stop 33): rebuild the runner
# code as 173f511 was made (e85aa5d + the diff of 4d3e7fc), the cases folder from the committed
# suite (checked against sha256sums.txt) and the output folder from the committed reports, then
# start both runners with session.sh. Idempotent: what exists is kept.
set -euo pipefail
MAIN=/work/main; R=$MAIN/benchmarks/results/heldout_seed9
[ -x $MAIN/.venv/bin/python ] || make -C $MAIN install
if [ ! -d /work/wt9d ]; then
  git -C $MAIN worktree add -q --detach /work/wt9d e85aa5d
  git -C $MAIN diff 4d3e7fc^ 4d3e7fc | git -C /work/wt9d apply
fi
git -C /work/wt9d status --short   # expect: M bench_diagnose.py, M docs/inference.md, ?? memo.py, ?? test_memo.py
mkdir -p /work/runs/concealedS9 /work/runs/diagnoseS9c /work/runs/storeS9
cp -n $R/suite/* /work/runs/concealedS9/
(cd /work/runs/concealedS9 && grep -v -e truth -e audit $R/sha256sums.txt | sha256sum -c --quiet -)
cp -n $R/case_*.json $R/case_*.png /work/runs/diagnoseS9c/
cp $R/runner/s9d.sh $R/runner/session.sh /work/runs/ && chmod +x /work/runs/*.sh
bash /work/runs/session.sh
