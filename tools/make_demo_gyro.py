"""Regenerate the bundled demo gyro trace (src/gyrodeblur/data/demo_gyro.gcsv).

Origin: generated, not recorded: gyrodeblur.shake.synthetic_hand_shake with the seed
below (two-band hand-shake model, 200 Hz, 2 s), so it is ours to ship. Run from the
repository root: python tools/make_demo_gyro.py
"""

from gyrodeblur.gyrolog import write_gcsv
from gyrodeblur.shake import synthetic_hand_shake

SEED = 7

if __name__ == "__main__":
    log = synthetic_hand_shake(2.0, 200.0, seed=SEED, sway_rms=(0.2, 0.25, 0.35),
                               tremor_rms=(0.1, 0.1, 0.08), t0=100.0)
    write_gcsv("src/gyrodeblur/data/demo_gyro.gcsv", log,
               extra_header={"note": f"synthetic hand shake, gyrodeblur.shake seed {SEED}"})
