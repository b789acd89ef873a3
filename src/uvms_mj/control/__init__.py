"""Controllers: the interface (:mod:`.base`), the registry (:mod:`.registry`) and the built-ins
(``rac``, ``rac_dob``, ``pd``, ``station_pid``, ``task_priority``)."""

from uvms_mj.control.base import ENTRY_POINT_GROUP, Command, Controller, ControllerError, Measurement, register
from uvms_mj.control.registry import available, create

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
