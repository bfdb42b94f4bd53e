"""Plane geometry: line and circle sets (shapes), Sim(2) (sim2), the frame tree of a session
(frame_tree), poses between stamps (pose_interpolation), segments near each other
(segment_pairs)."""
