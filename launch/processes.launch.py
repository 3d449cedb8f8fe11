"""`ros2 launch ema_sim processes.launch.py maneuver:=step use_sim_time:=true`: the suite in the `processes` layout.

The same processes as `ema launch --layout processes` (ema_sim.run.RunDescription); `ros2 launch ema_sim
processes.launch.py --show-args` lists the arguments (ema launch's options;
`use_sim_time:=true` and `lockstep:=true` are the same: every node on `/clock`, frame by frame).
"""

from ema_sim.launching import generate


def generate_launch_description():  # noqa: ANN201, D103
    return generate("processes")
