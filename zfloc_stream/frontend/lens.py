"""Lens distortion removed from a camera's images: a depth image, its labels and its colour
image become those of the ideal pinhole camera K (the frame keeps K), so back-projection
(z * K^-1 [u, v, 1]) is right at the image borders too.

Each output pixel takes the input pixel its ray falls on through the distortion model
(nearest neighbour: a depth or label is never blended across an edge into a value no
surface has); rays that fall outside the input image read 0, 'no reading' / 'unknown'.
This is OpenCV's initUndistortRectifyMap with R = I and the new camera K, written in
numpy (tests compare the two). Models, by their ROS / Foxglove names:

- plumb_bob (k1 k2 p1 p2 k3) and rational_polynomial (k1 k2 p1 p2 k3 k4 k5 k6): radial
  and tangential (missing coefficients are 0);
- equidistant / kannala_brandt / fisheye (k1 k2 k3 k4): the fisheye model.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

PINHOLE_MODELS = ("plumb_bob", "rational_polynomial", "brown_conrady")
FISHEYE_MODELS = ("equidistant", "kannala_brandt", "fisheye")
MODELS = PINHOLE_MODELS + FISHEYE_MODELS


def is_distorted(D) -> bool:
    return any(float(v) != 0.0 for v in D)


def supported(model: str) -> bool:
    return model.lower() in MODELS


def undistort(images, K: np.ndarray, model: str, D) -> list:
    """The images (HxW or HxWx3, one pixel grid; None kept) as the undistorted camera K
    would see them. `model` must be supported()."""
    shape = next((im.shape[:2] for im in images if im is not None), None)
    if shape is None:
        return list(images)
    src, inside = _map(K.astype(float).tobytes(), model.lower(), tuple(float(v) for v in D), shape)
    out = []
    for im in images:
        if im is None:
            out.append(None)
            continue
        flat = im.reshape(shape[0] * shape[1], *im.shape[2:])
        u = flat[src].reshape(im.shape)
        u[~inside] = 0
        out.append(u)
    return out


@lru_cache(maxsize=8)
def _map(K_bytes: bytes, model: str, D: tuple, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(flat source pixel of every output pixel, whether it lies inside the image)."""
    K = np.frombuffer(K_bytes, dtype=float).reshape(3, 3)
    h, w = shape
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    v, u = np.mgrid[0:h, 0:w].astype(float)
    with np.errstate(all="ignore"):  # huge coefficients send rays off the image: read as outside
        y = (v - cy) / fy
        x = (u - cx - s * y) / fx
        xd, yd = (_fisheye if model in FISHEYE_MODELS else _radial_tangential)(x, y, D)
        us = np.rint(fx * xd + s * yd + cx)
        vs = np.rint(fy * yd + cy)
        inside = np.isfinite(us) & np.isfinite(vs) & (us >= 0) & (us < w) & (vs >= 0) & (vs < h)
    src = np.where(inside, np.where(inside, vs, 0).astype(np.int64) * w + np.where(inside, us, 0).astype(np.int64), 0)
    return src, inside


def _radial_tangential(x, y, D):
    k1, k2, p1, p2, k3, k4, k5, k6 = (list(D) + [0.0] * 8)[:8]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return xd, yd


def _fisheye(x, y, D):
    k1, k2, k3, k4 = (list(D) + [0.0] * 4)[:4]
    r = np.hypot(x, y)
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    scale = np.divide(theta_d, r, out=np.ones_like(r), where=r > 1e-12)
    return x * scale, y * scale
