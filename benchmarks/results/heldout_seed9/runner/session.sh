#!/bin/bash
# copy finished seed-9 reports into the repo unread; restart runners if down
R=/work/main/benchmarks/results/heldout_seed9
for f in /work/runs/diagnoseS9c/case_*.json; do
  b=$(basename $f .json)
  if [ ! -e $R/$b.json ]; then cp $f $R/; cp /work/runs/diagnoseS9c/$b.png $R/ 2>/dev/null; echo "copied $b $(date -u -r $f +%H:%M)"; fi
done
for r in r1 r2; do
  if [ $r = r1 ]; then k="ids 00,02"; else k="ids 01,03"; fi
  if ! pgrep -f "$k" > /dev/null; then
    if [ $r = r1 ]; then h=00,02,04,06,09,11,13,16,18,20,08; else h=01,03,05,07,10,12,15,17,19,21,14; fi
    setsid nohup /work/runs/s9d.sh $h $r > /dev/null 2>&1 &
    echo "started $r $(date -u +%H:%M:%S)"
  fi
done
