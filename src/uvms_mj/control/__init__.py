"""Controllers: the interface, the registry and the built-ins (``rac``, ``rac_dob``, ``pd``)."""

from uvms_mj.control.base import (
    ENTRY_POINT_GROUP,
    Command,
    Controller,
    ControllerError,
    Measurement,
    available,
    create,
    register,
)

__all__ = [
    "ENTRY_POINT_GROUP",
    "Command",
    "Controller",
    "ControllerError",
    "Measurement",
    "available",
    "create",
    "register",
]
