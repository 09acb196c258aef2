# Sourced by this folder's scripts: they work in this folder wherever they are started
# from, with the Shield capture's folder in $data (under GYRODEBLUR_SHARED_DATA, else
# ../../../shared/data), or stop saying what to set.
if [ -n "${GYRODEBLUR_SHARED_DATA:-}" ]; then
  shared=$(cd "$GYRODEBLUR_SHARED_DATA" 2>/dev/null && pwd) || {
    echo "$0: GYRODEBLUR_SHARED_DATA=$GYRODEBLUR_SHARED_DATA is not a folder" >&2
    exit 2
  }
  export GYRODEBLUR_SHARED_DATA=$shared     # as this script's children must read it
fi
cd "$(dirname "${BASH_SOURCE[0]}")"
data=${shared:-../../../shared/data}/real/shield-tablet
if [ ! -f "$data/frames.txt" ]; then
  echo "$0: no Shield capture at $data (from $PWD): set GYRODEBLUR_SHARED_DATA to the shared data folder" >&2
  exit 2
fi
