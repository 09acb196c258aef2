#!/usr/bin/env bash
# Deblur the Shield-tablet frames that the gyro log covers, into ./shield-out/.
# Usage (from this folder): ./deblur_frames.sh [extra gyrodeblur deblur options]
set -euo pipefail
data=../../../shared/data/real/shield-tablet
mkdir -p shield-out
i=0
while read -r ts exposure; do
  i=$((i + 1))
  frame=$(printf "%04d" "$i")
  case $frame in 0002|0003|0004|0005|0006) ;; *) continue ;; esac
  start=$(python3 -c "print($ts * 1e-9)")
  gyrodeblur deblur "$data/$frame.jpg" --capture capture_0003.json --exposure-start "$start" \
    -o "shield-out/$frame.jpg" --overwrite "$@"
done < "$data/frames.txt"
