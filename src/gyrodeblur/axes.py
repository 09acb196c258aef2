"""Axis mappings from a gyro log's frame to the camera frame.

The camera frame is OpenCV's: x right, y down, z forward (along the optical axis). A
mapping is a proper rotation ``M`` with ``w_camera = M @ w_log``. It can be written

* as three letters, the i-th naming the log axis (``X``, ``Y`` or ``Z``; lowercase =
  negated) that *is* the camera's i-th axis: ``"XYZ"`` is the identity, ``"yxz"`` says
  camera x = -log y, camera y = -log x, camera z = -log z (an Android phone's back camera,
  its photo in the sensor's layout, from the device's axes: y up and z out of the screen
  in the natural orientation; see :data:`NAMED_AXES`);
* as a 3x3 matrix (nested lists), rows = camera axes;
* as a name from :data:`NAMED_AXES`.

Only proper rotations are accepted (orthonormal, determinant +1): a reflection such as
swapping two axes without a sign change is physically impossible for two rigidly
attached frames, and silently accepting one flips the direction of a rotation.
"""

from __future__ import annotations

import itertools

import numpy as np

from .errors import InputError

__all__ = ["parse_axes", "axes_to_letters", "PROPER_AXIS_LETTERS", "PHONE_AXIS_LETTERS",
           "NAMED_AXES"]

#: Named mappings, log frame -> camera frame. ``android-back-camera-<θ>``: Android device
#: axes (x right, y up, z out of the screen, in the device's natural orientation) to the
#: frame of a back camera's photo in its sensor's layout (rows in readout order), for the
#: camera's ``SENSOR_ORIENTATION`` θ (the clockwise turn, degrees, that shows the sensor's
#: image upright in the natural orientation). 0: the sensor's rows run along the device's
#: x axis; 90, most phones' (and the Shield tablet's): its x axis is the device's -y.
#: ``android-back-camera`` is the 90 of most phones. ``ios-back-camera``: Core Motion's
#: device axes (the same as Android's) to an iPhone's or iPad's back camera, whose sensor
#: image is upright with the device turned so that its bottom (the home button) is on the
#: right (EXIF orientation 1 there, 6 for a portrait photo): the sensor orientation 90.
NAMED_AXES = {
    "identity": "XYZ",
    "android-back-camera-0": "Xyz",
    "android-back-camera-90": "yxz",
    "android-back-camera-180": "xYz",
    "android-back-camera-270": "YXz",
    "android-back-camera": "yxz",
    "ios-back-camera": "yxz",
}


def _letters_matrix(spec: str) -> tuple[np.ndarray | None, str | None]:
    if len(spec) != 3 or any(c not in "XYZxyz" for c in spec):
        return None, ("must be three letters from X, Y, Z (lowercase = negated)"
                      + ("" if len(spec) == 3 else f" or a name: {', '.join(NAMED_AXES)}"))
    if len({c.upper() for c in spec}) != 3:
        return None, "must name each of X, Y, Z exactly once"
    m = np.zeros((3, 3))
    for i, c in enumerate(spec):
        m[i, "XYZ".index(c.upper())] = 1.0 if c.isupper() else -1.0
    if np.linalg.det(m) < 0:
        return None, ("is a reflection (determinant -1), not a rotation: negate one axis "
                      "or swap two more")
    return m, None


def parse_axes(spec, *, source: str | None = "orientation") -> np.ndarray:
    """Turn an axis-mapping spec into a 3x3 rotation matrix ``M`` (``w_cam = M w_log``).

    Parameters
    ----------
    spec : str or array-like (3, 3)
        Letters (``"XYZ"``, ``"Xyz"``...), a name from :data:`NAMED_AXES`, or a matrix.
    source : str
        Named in the error message (the file or option the spec came from).

    Raises
    ------
    InputError
        If the spec is not a proper rotation, saying why.
    """
    if isinstance(spec, str):
        key = spec.strip()
        key = NAMED_AXES.get(key, key)
        m, why = _letters_matrix(key)
        if m is None:
            raise InputError(source, f"axis mapping {spec!r} {why}")
        return m
    try:
        m = np.array(spec, dtype=np.float64)      # a copy: the caller's array may change
    except (TypeError, ValueError):
        raise InputError(source, f"axis mapping {spec!r} is neither letters nor a 3x3 "
                                 "matrix") from None
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise InputError(source, f"axis matrix must be 3x3 finite numbers, got shape {m.shape}")
    err = np.abs(m @ m.T - np.eye(3)).max()
    if err > 1e-6:
        raise InputError(source, f"axis matrix {m.tolist()} is not orthonormal "
                                 f"(|M M^T - I| = {err:.2g})")
    det = np.linalg.det(m)
    if det < 0:
        raise InputError(source, f"axis matrix {m.tolist()} has determinant {det:+.0f}: a "
                                 "reflection, not a rotation")
    return m


def axes_to_letters(m: np.ndarray) -> str | None:
    """Letters for a signed-permutation rotation, or ``None`` if ``m`` is not one."""
    m = np.asarray(m)
    out = []
    for row in m:
        j = int(np.argmax(np.abs(row)))
        if abs(abs(row[j]) - 1) > 1e-9 or np.abs(np.delete(row, j)).max() > 1e-9:
            return None
        out.append("XYZ"[j] if row[j] > 0 else "xyz"[j])
    return "".join(out)


def _all_proper() -> tuple[str, ...]:
    out = []
    for perm in itertools.permutations("XYZ"):
        for signs in itertools.product((True, False), repeat=3):
            s = "".join(c if up else c.lower() for c, up in zip(perm, signs))
            if _letters_matrix(s)[0] is not None:
                out.append(s)
    return tuple(out)


#: The 24 proper signed axis permutations, as letter strings.
PROPER_AXIS_LETTERS: tuple[str, ...] = _all_proper()

#: The 8 of them that keep the camera's optical axis (z) on the log's z axis, either way:
#: a phone's or tablet's own camera looks out of its back (camera z = -log z, the
#: ``android-back-camera-*`` of :data:`NAMED_AXES`) or out of its screen (+log z), while
#: its sensor's rows may run along the device's x or y axis, either way. So these are the
#: mappings possible from a phone's device axes (x right, y up, z out of the screen) to
#: the camera frame of a photo that phone took.
PHONE_AXIS_LETTERS: tuple[str, ...] = tuple(a for a in PROPER_AXIS_LETTERS if a[2] in "Zz")
