"""The online loop: Localizer.push fuses a frame, applies landed rounds, maybe starts a round,
decides the frame's status and reports (localizer); rounds on a schedule (scheduler); each
frame's hits against the tracked place (monitor); a kidnap test (recovery); steps the sensor
cannot have made (odometry_jump); whether the map explains the frames at all (map_match)."""
