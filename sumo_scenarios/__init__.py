"""The highway driving domain (paper Section 5.2) on SUMO through libsumo."""
