"""rosbag2 bags with MCAP storage, written and read through rosbags: no ROS install needed.

The node suite's recorder writes every topic as it arrives (raw CDR, no re-serialisation) with the
test's parameters in the bag's ``custom_data`` and, as JSON, on the latched ``/ema/test`` topic.
:func:`read_bag` turns one channel of a bag into :class:`~ema_sim.io.measured.MeasuredData` in degrees
through the calibration curves recorded with it. A bag cut short is still read: one whose writer was
stopped by SIGTERM or Ctrl-C is complete; one whose ``metadata.yaml`` never got written (the writer
was killed) is read record by record from its MCAP file up to the last complete chunk.

One job per module: :mod:`.writer` (and :mod:`.storage`, rosbags' internals), :mod:`.reader`,
:mod:`.reindex`; :mod:`.layout` holds what they share.
"""

from ema_sim.io.bag.layout import METADATA_KEYS, SIDES
from ema_sim.io.bag.reader import BagInfo, bag_channels, bag_info, read_bag, read_fault_truth, read_joint_topic
from ema_sim.io.bag.reindex import ReindexReport, reindex_bag
from ema_sim.io.bag.writer import BagWriter, write_bag

__all__ = ["METADATA_KEYS", "SIDES", "BagInfo", "BagWriter", "ReindexReport", "bag_channels", "bag_info", "read_bag",
           "read_fault_truth", "read_joint_topic", "reindex_bag", "write_bag"]
