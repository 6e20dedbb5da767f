"""State estimation from the sensors' measurement: a gain-scheduled Kalman filter of the CM."""
