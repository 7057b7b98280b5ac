"""Independent reading of an MCAP file with the `mcap` and `mcap-ros2-support`
packages: prints, as JSON, the profile, each channel's topic, encodings,
schema and counted messages, the first and last decoded JointState, the
first JSON payload of each JSON channel, and the metadata records."""
import json
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def joint_state(msg):
    return {
        "sec": msg.header.stamp.sec,
        "nanosec": msg.header.stamp.nanosec,
        "name": list(msg.name),
        "position": list(msg.position),
        "velocity": list(msg.velocity),
        "effort": list(msg.effort),
    }


def main(path):
    out = {"channels": {}, "metadata": {}, "first": {}, "last": {}}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        out["profile"] = reader.get_header().profile
        summary = reader.get_summary()
        for cid, ch in summary.channels.items():
            sch = summary.schemas[ch.schema_id]
            out["channels"][ch.topic] = {
                "message_encoding": ch.message_encoding,
                "schema": sch.name,
                "schema_encoding": sch.encoding,
                "statistics_count": summary.statistics.channel_message_counts.get(cid, 0),
                "count": 0,
            }
        for _schema, channel, message in reader.iter_messages():
            out["channels"][channel.topic]["count"] += 1
            if channel.message_encoding == "json" and channel.topic not in out["first"]:
                out["first"][channel.topic] = json.loads(message.data)
        for _s, channel, _m, decoded in reader.iter_decoded_messages(topics=["/joint_states", "/joint_reference"]):
            if channel.topic not in out["first"]:
                out["first"][channel.topic] = joint_state(decoded)
            out["last"][channel.topic] = joint_state(decoded)
        for record in reader.iter_metadata():
            out["metadata"][record.name] = dict(record.metadata)
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
