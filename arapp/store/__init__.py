"""Per-user storage: the config folder (`user_config`: secrets, remembered choices) and camera calibrations
stored per camera and resolution (`camera_store`). Imports tracking only."""
