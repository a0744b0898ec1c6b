#!/usr/bin/env python3
"""What TensorBoard's own reader finds in a folder of event files, for the tests
(worker/tests/tensorboard.rs): `tensorboard-scalars.py DIR` prints one JSON object,
{"scalars": {TAG: [[STEP, VALUE], ...]}, "texts": {TAG: TEXT}, "hparams": {NAME: VALUE}},
read with the `tensorboard` package's EventAccumulator (every event kept) and its hparams
plugin's own protocol buffers.
"""

import json
import sys

from tensorboard.backend.event_processing import event_accumulator
from tensorboard.plugins.hparams import plugin_data_pb2


def main(folder):
    accumulator = event_accumulator.EventAccumulator(
        folder,
        size_guidance={event_accumulator.SCALARS: 0, event_accumulator.TENSORS: 0},
    )
    accumulator.Reload()
    tags = accumulator.Tags()
    scalars = {
        tag: [[event.step, event.value] for event in accumulator.Scalars(tag)]
        for tag in tags["scalars"]
    }
    texts = {}
    for tag in tags["tensors"]:
        for event in accumulator.Tensors(tag):
            texts[tag] = event.tensor_proto.string_val[0].decode()
    hparams = {}
    for content in accumulator.PluginTagToContent("hparams").values():
        data = plugin_data_pb2.HParamsPluginData.FromString(content)
        for name, value in data.session_start_info.hparams.items():
            hparams[name] = getattr(value, value.WhichOneof("kind"))
    print(json.dumps({"scalars": scalars, "texts": texts, "hparams": hparams}))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: tensorboard-scalars.py DIR")
    main(sys.argv[1])
