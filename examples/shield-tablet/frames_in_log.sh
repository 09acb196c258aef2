#!/usr/bin/env bash
# Print "FRAME START" for the Shield frames that the gyro log covers (0002-0006): the frame
# number and its exposure start in seconds (frames.txt holds nanoseconds).
# Usage (from this folder): ./frames_in_log.sh
set -euo pipefail
data=../../../shared/data/real/shield-tablet
i=0
while read -r ts exposure; do
  i=$((i + 1))
  frame=$(printf "%04d" "$i")
  case $frame in 0002|0003|0004|0005|0006) ;; *) continue ;; esac
  echo "$frame $(python3 -c "print($ts * 1e-9)")"
done < "$data/frames.txt"
