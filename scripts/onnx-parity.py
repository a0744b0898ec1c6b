#!/usr/bin/env python3
"""An exported policy run with ONNX Runtime against the actions crm took, for the tests
(tests/onnx.rs): `onnx-parity.py MODEL.onnx SAMPLES.json` prints one JSON object: the largest
absolute difference between ONNX Runtime's `action` and crm's over every sample, the number of
samples, the model's metadata, and whether `action_clipped` is `action` clipped to [-1, 1].
The model is checked with onnx's checker first.
"""

import json
import sys

import numpy as np
import onnx
import onnxruntime


def main(model_path, samples_path):
    onnx.checker.check_model(onnx.load(model_path), full_check=True)
    with open(samples_path) as f:
        samples = json.load(f)
    session = onnxruntime.InferenceSession(model_path, providers=["CPUExecutionProvider"])
    observation = np.asarray(samples["observation"], dtype=np.float32)
    stage = np.asarray(samples["stage"], dtype=np.int64)
    expected = np.asarray(samples["action"], dtype=np.float32)
    action, clipped = session.run(
        ["action", "action_clipped"], {"observation": observation, "stage": stage}
    )
    meta = session.get_modelmeta().custom_metadata_map
    print(
        json.dumps(
            {
                "samples": int(len(stage)),
                "max_abs_diff": float(np.max(np.abs(action - expected))),
                "clipped_ok": bool(np.array_equal(clipped, np.clip(action, -1.0, 1.0))),
                "metadata": dict(meta),
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
