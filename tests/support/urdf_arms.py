"""Arms for the URDF tests: our lift-column arm (rrbc_core/data/robots/lift_arm.urdf: a prismatic lift, six revolute
joints and a spindle that mimics a joint off the chain) and the library's simulator of measurements with joint
columns (`rrbc_core.simulation.arm_data`)."""

from rrbc_core.models.urdf import bundled_urdf
from rrbc_core.simulation.arm_data import chain_measurements, random_errors, random_poses

LIFT_ARM = bundled_urdf("lift_arm")

__all__ = ["LIFT_ARM", "chain_measurements", "random_errors", "random_poses"]
