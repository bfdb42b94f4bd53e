"""Floorplans: the raster floorplan the localizer aligns to (floorplan), read from images and
ROS maps (raster_files) or drawn from vector files (readers, segment_merging, vector), one
entry point (loading), and occupancy maps built from laser logs (map_from_log)."""
