"""Geometry: rigid transforms (`transforms`: the one convention, robot = R @ sensor + t) and point sets (`points`:
the one point validator, degeneracy checks and their thresholds, the local principal frame used to interpolate)."""
