"""ROS-free core for recording and reading rosbag2 bags in MCAP format.

Write: ``BagWriter`` (bag directory with metadata.yaml version 9 and chunked, compressed, split MCAP
files; crash safe chunk by chunk). Read: ``Bag`` / ``bag_info`` / ``read_columns`` (vectorised CDR
decoding into numpy column batches, streamed chunk by chunk) / ``iter_messages`` (generic).
Repair: ``reindex`` (metadata.yaml from the data; cut-short files finished with summary and footer;
files damaged otherwise left as they are; the loss found kept). ``Bag.lost_data()`` lists the
problems that lost recorded messages (``DATA_LOSS_KINDS``); ``Bag.loss`` / ``BagInfo.loss``
(``LossCount``) count them: recorded (metadata.yaml, MCAP summaries) against readable, per topic.
Analysis (per feeder, feeders told apart by namespace): :mod:`feeder_ros.bag.analysis`.
"""

from feeder_ros.bag.cdr import ColumnPlan, decode_cdr
from feeder_ros.bag.errors import (
    DATA_LOSS_KINDS,
    BagError,
    BagProblem,
    BagWarning,
    CorruptRecordError,
    MessageDefinitionError,
    MissingBagError,
    UnknownTypeError,
    UnsupportedLayoutError,
    WriterStateError,
)
from feeder_ros.bag.loss import LossCount, TopicLoss
from feeder_ros.bag.reader import (
    LOG_TIME,
    PUBLISH_TIME,
    Bag,
    BagInfo,
    Checks,
    ColumnBatch,
    RawMessage,
    TopicInfo,
    bag_info,
    concat_batches,
    iter_messages,
    read_columns,
    read_tables,
)
from feeder_ros.bag.reindex import reindex
from feeder_ros.bag.schemas import ros2msg_schema, type_description_hash
from feeder_ros.bag.writer import BagWriter, default_qos_yaml

__all__ = [
    "DATA_LOSS_KINDS",
    "LOG_TIME",
    "PUBLISH_TIME",
    "Bag",
    "BagError",
    "BagInfo",
    "BagProblem",
    "BagWarning",
    "BagWriter",
    "Checks",
    "ColumnBatch",
    "ColumnPlan",
    "CorruptRecordError",
    "LossCount",
    "MessageDefinitionError",
    "MissingBagError",
    "RawMessage",
    "TopicInfo",
    "TopicLoss",
    "UnknownTypeError",
    "UnsupportedLayoutError",
    "WriterStateError",
    "bag_info",
    "concat_batches",
    "decode_cdr",
    "default_qos_yaml",
    "iter_messages",
    "read_columns",
    "read_tables",
    "reindex",
    "ros2msg_schema",
    "type_description_hash",
]
