#!/usr/bin/env bash
# Print "FRAME START" for the Shield frames that the gyro log covers (0002-0006): the frame
# number and its exposure start in seconds (frames.txt holds nanoseconds).
# Usage (from any folder; the outputs go to this one): ./frames_in_log.sh
set -euo pipefail
shared=${GYRODEBLUR_SHARED_DATA:+$(realpath -m "$GYRODEBLUR_SHARED_DATA")}
cd "$(dirname "$0")"    # the paths below are this folder's
data=${shared:-../../../shared/data}/real/shield-tablet
if [ ! -f "$data/frames.txt" ]; then
  echo "$0: no Shield capture at $(realpath -m "$data"): set GYRODEBLUR_SHARED_DATA to the shared data folder" >&2
  exit 2
fi
awk 'NR >= 2 && NR <= 6 { printf "%04d %.6f\n", NR, $1 * 1e-9 }' "$data/frames.txt"
