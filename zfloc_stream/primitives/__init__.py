"""Paper section 3.1: lines and circles from 2D wall points, one implementation for the BEV
and the floorplan (extract), by region growing (line_growing) and RANSAC circle fits
(circle_fitting)."""
