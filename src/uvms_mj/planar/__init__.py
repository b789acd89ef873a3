"""The paper robot's planar closed forms (to become test oracles)."""
