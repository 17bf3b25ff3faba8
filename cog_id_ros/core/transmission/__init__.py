"""Joint space and actuator space: the map between a legged robot's serial joints and its
motors."""
