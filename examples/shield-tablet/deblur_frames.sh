#!/usr/bin/env bash
# Deblur the Shield-tablet frames that the gyro log covers, into ./shield-out/, with the
# hand-worked capture_0003.json, or with another description given as CAPTURE (say
# CAPTURE=shield-out/calibrated.json after ./calibrate_frames.sh).
# Usage (from any folder; the outputs go to this one): [CAPTURE=file.json] ./deblur_frames.sh [extra gyrodeblur deblur options]
set -euo pipefail
. "$(dirname "$0")/shared_data.sh"      # cd here; $data: the capture's folder
capture=${CAPTURE:-capture_0003.json}
frames=$(./frames_in_log.sh)
mkdir -p shield-out
while read -r frame start; do
  gyrodeblur deblur "$data/$frame.jpg" --capture "$capture" --exposure-start "$start" \
    --gyro "$data/sensor_events.txt" -o "shield-out/$frame.jpg" --overwrite "$@"
done <<< "$frames"
