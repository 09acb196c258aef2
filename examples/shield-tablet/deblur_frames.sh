#!/usr/bin/env bash
# Deblur the Shield-tablet frames that the gyro log covers, into ./shield-out/, with the
# hand-worked capture_0003.json, or with another description given as CAPTURE (say
# CAPTURE=shield-out/calibrated.json after ./calibrate_frames.sh), and the Shield's sensor
# log (whatever gyro.path the description names), or another given as GYRO (the options
# after the script's name cannot name --capture or --gyro again: given twice is refused).
# Usage (from any folder; the outputs go to this one): [CAPTURE=file.json] [GYRO=log] ./deblur_frames.sh [extra gyrodeblur deblur options]
set -euo pipefail
. "$(dirname "$0")/shared_data.sh"      # cd here; $data: the capture's folder
capture=${CAPTURE:-capture_0003.json}
gyro=${GYRO:-$data/sensor_events.txt}
frames=$(./frames_in_log.sh)
mkdir -p shield-out
while read -r frame start; do
  gyrodeblur deblur "$data/$frame.jpg" --capture "$capture" --exposure-start "$start" \
    --gyro "$gyro" -o "shield-out/$frame.jpg" --overwrite "$@"
done <<< "$frames"
