#!/usr/bin/env bash
# Print "FRAME START" for the Shield frames that the gyro log covers (0002-0006): the frame
# number and its exposure start in seconds (frames.txt holds nanoseconds).
# Usage (from any folder; the outputs go to this one): ./frames_in_log.sh
set -euo pipefail
. "$(dirname "$0")/shared_data.sh"      # cd here; $data: the capture's folder
awk 'NR >= 2 && NR <= 6 { printf "%04d %.6f\n", NR, $1 * 1e-9 }' "$data/frames.txt"
