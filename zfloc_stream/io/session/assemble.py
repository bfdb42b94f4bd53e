"""Input frames rebuilt from their decoded messages: the one place that does it, used by
the writer (to hand back the frame as logged) and by the reader (to replay it)."""

from __future__ import annotations

from ...errors import SessionLogError
from ...frontend import lens
from ...frames import CameraFrame, LaserFrame
from ..messages import depth_in_metres
from . import schemas as S


LENS_NOTE = "/camera/calibration distortion model"  # the start of the note, one per read


def camera_frame_from_msgs(depth, labels, calibration, odometry, ground_truth, heading_axis: str, timestamp: float, image=None,
                           notes: list[str] | None = None) -> CameraFrame:
    """depth/labels: RawImage (either may be None when a colour image is given);
    calibration: CameraCalibration; odometry / ground_truth: PoseInFrame (ground_truth may
    be None); image: RawImage rgb8/bgr8 or CompressedImage, or None. Float depth in
    millimetres is converted and lens distortion removed (lens.py); `notes` gets what
    was changed or ignored on the way."""
    d, note = (None, None) if depth is None else depth_in_metres(depth)
    if note is not None and notes is not None:
        notes.append(note)
    rgb = None if image is None else S.image_from_msg(image)
    lab = None if labels is None else S.labels_from_msg(labels)
    K, width, height = S.calibration_from_msg(calibration)
    shape = d.shape if d is not None else rgb.shape[:2]
    if (width, height) != (0, 0) and (height, width) != shape:
        what = "depth" if d is not None else "the colour image"
        raise SessionLogError(f"calibration is for {width}x{height} images but {what} is {shape[1]}x{shape[0]}")
    model, D = S.distortion_from_msg(calibration)
    if lens.is_distorted(D):
        if lens.supported(model):  # images of another size are left as they are, for CameraFrame to refuse
            ims = (d, lab, rgb)
            same = [im is not None and im.shape[:2] == shape for im in ims]
            fixed = lens.undistort([im if ok else None for im, ok in zip(ims, same)], K, model, D)
            d, lab, rgb = (f if ok else im for im, f, ok in zip(ims, fixed, same))
        elif notes is not None:
            notes.append(f"{LENS_NOTE} '{model}' is not supported ({', '.join(lens.MODELS)}): its coefficients "
                         f"{list(D)} ignored, images used as they are")
    T = S.matrix_from_pose(odometry.pose)
    gt = None if ground_truth is None else S.planar_pose_from_pose(ground_truth.pose, heading_axis)
    return CameraFrame(d, lab, K, T, timestamp, ground_truth=gt, rgb=rgb)


def laser_frame_from_msgs(scan, range_min: float, range_max: float, odometry, ground_truth, heading_axis: str, timestamp: float) -> LaserFrame:
    ranges, angle_min, angle_increment = S.scan_from_msg(scan)
    T = S.matrix_from_pose(odometry.pose)
    gt = None if ground_truth is None else S.planar_pose_from_pose(ground_truth.pose, heading_axis)
    return LaserFrame(ranges, angle_min, angle_increment, range_min, range_max, T, timestamp, ground_truth=gt)
