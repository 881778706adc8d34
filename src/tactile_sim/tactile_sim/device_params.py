"""Parameters of the hidden object and the simulated sensor device, shared by
``sim_rig`` and ``sim_sensor_device``.

name -> (default, description); the object ones go to
:func:`~tactile_sim.objects.make_object`; ``model.*`` configure
:class:`~tactile_sim.sensor_model.SensorModelConfig`, ``fault.*`` the
injected faults (:class:`~tactile_sim.sensor_device.FaultConfig`).
"""

DEVICE_PARAMETERS = {
    "model.stiffness_pa_per_m": (2.0e7, "skin pressure per metre of penetration", {"gt": 0.0}),
    "model.spread_m": (0.0025, "std of the skin's spatial spread", {"gt": 0.0}),
    "model.counts_per_newton": (10000.0, "counts per newton (the driver's calibration)", {"gt": 0.0}),
    "model.noise_counts": (2.0, "std of the taxel noise", {"ge": 0.0}),
    "fault.garbage_prob": (0.0, "per frame: a burst of garbage bytes", {"ge": 0.0, "le": 1.0}),
    "fault.crc_error_prob": (0.0, "per frame: a corrupted byte", {"ge": 0.0, "le": 1.0}),
    "fault.drop_prob": (0.0, "per frame: frame not sent", {"ge": 0.0, "le": 1.0}),
    "fault.stuck_taxel": (-1, "index of a stuck taxel (-1: none)", {"ge": -1}),
    "fault.stuck_value": (4000, "value of the stuck taxel", {"ge": 0}),
    "fault.stuck_after_s": (0.0, "time after the first frame when the taxel sticks", {"ge": 0.0}),
    "fault.disconnect_at_s": (-1.0, "time after the first frame of a disconnect (negative: never)"),
    "fault.disconnect_for_s": (1.0, "disconnect length", {"ge": 0.0}),
}

OBJECT_PARAMETERS = {
    "object": ("circle", "hidden object: a built-in name or a .csv/.stl/.obj path"),
    "mode": ("2d", "2d (prism contour) or 3d", {"choices": ("2d", "3d")}),
    "object_xy_m": ([0.50, 0.0], "object centre on the table (world)", {"length": 2}),
    "object_yaw_rad": (0.0, "object yaw"),
    "object_scale": (1.0, "object scale", {"gt": 0.0}),
    "prism_height_m": (0.12, "prism height in 2D mode", {"gt": 0.0}),
}
