"""Default topic names and frame ids of the graph (see the README topic table).

Every node takes these as defaults; users remap them with
``--ros-args -r /old:=/new``.
"""

# Frames. ``world`` is the robot base frame: x forward (towards the object),
# z up, origin at the arm base on the table top.
WORLD_FRAME = "world"
FINGERTIP_FRAME = "fingertip"

# Sensing.
CONTACTS = "/tactile/contacts"
# Per-frame contact while in contact (one point; an empty cloud at the release): a slide's servo input.
CONTACT_FRAMES = "/tactile/contact_frames"
TAXELS = "/tactile/taxels"
SENSOR_DECIDED = "/tactile/decided_through"  # DiagnosticStatus: frames judged up to a stamp, contacts sent so far
DIAGNOSTICS = "/diagnostics"

# Estimation.
VARIANCE_MAP = "/gpis/variance_map"
OCCUPANCY = "/gpis/occupancy"
SURFACE = "/gpis/surface"

# Planning.
REQUEST = "/planner/request"
GOAL = "/planner/goal"
PATH = "/planner/path"
PLANNER_STATUS = "/planner/status"

# Arm.
JOINT_TRAJECTORY = "/joint_trajectory_controller/joint_trajectory"
JOINT_STATES = "/joint_states"
FINGERTIP_POSE = "/arm/fingertip_pose"
ESTOP = "/arm/estop"
TOUCH_DONE = "/arm/touch_done"
# DiagnosticStatus: every frame up to a stamp judged by the driver and its contacts acted on (the simulated
# rig's clock waits for it, so that a stop after a contact lands in time however loaded the machine).
ARM_ACTED = "/arm/acted_through"

# Simulation.
CLOCK = "/clock"

# ROS's own (recordings leave them out).
ROSOUT = "/rosout"
PARAMETER_EVENTS = "/parameter_events"
