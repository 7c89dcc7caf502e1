"""A writer of samples that cannot be read as autoware_control_msgs/Control: a one-byte struct
under Control's type name (Cyclone DDS matches by name), forty of them on the controller's
topic. Prints one JSON object. Run inside lonet.sh."""

import json
import time
from dataclasses import dataclass

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import uint8

from ros2_types import participant, writer


@dataclass
class Short(IdlStruct, typename="autoware_control_msgs::msg::dds_::Control_"):
    x: uint8


dp = participant()
out = writer(dp, "rt/control/trajectory_follower/control_cmd", Short, depth=1)
# Written once the node's subscription is matched (before it, a sample reaches nobody).
end = time.monotonic() + 20
while not out.get_matched_subscriptions():
    if time.monotonic() > end:
        raise SystemExit("the node's subscription never matched")
    time.sleep(0.02)
for _ in range(40):
    out.write(Short(x=7))
    time.sleep(0.05)
print(json.dumps({"written": 40}))
