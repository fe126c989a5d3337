"""The robot: its model (Pinocchio + joint terms), where it comes from (example-robot-data,
URDF, profiles), its parameter layout, friction laws and regressors."""
