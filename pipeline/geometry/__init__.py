"""Camera models, frames and rotations: from GPS/IMU/gimbal to projection matrices."""
