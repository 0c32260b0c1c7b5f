"""The robot corridor domain (paper Section 5.1) on pymunk."""
