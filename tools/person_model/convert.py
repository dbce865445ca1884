"""Converts MediaPipe's BlazePose models (from the mediapipe 0.10.14 wheel) to ONNX.

Run by tools/setup-person-model.sh inside its own virtual environment; see that script.
Writes person_detector.onnx and person_landmarks.onnx into the output folder.

The detector stores its weights compressed behind DENSIFY ops, which tf2onnx cannot read:
they are expanded first by running the TFLite interpreter (without its default delegates,
which return wrong expanded weights) and written back as plain constants.
"""

import importlib
import os
import subprocess
import sys
import tempfile
import zipfile

import numpy as np

DETECTOR = "mediapipe/modules/pose_detection/pose_detection.tflite"
LANDMARKS = "mediapipe/modules/pose_landmark/pose_landmark_full.tflite"


def densified(src, dst):
    """Writes `src` with every DENSIFY op replaced by the dense constant it computes."""
    import tensorflow as tf

    fb = importlib.import_module("tensorflow.lite.tools.flatbuffer_utils")
    schema = importlib.import_module("tensorflow.lite.python.schema_py_generated")
    model = fb.read_model(src)
    graph = model.subgraphs[0]
    densify = [
        i
        for i, code in enumerate(model.operatorCodes)
        if max(code.builtinCode, code.deprecatedBuiltinCode) == schema.BuiltinOperator.DENSIFY
    ]
    ops = [op for op in graph.operators if op.opcodeIndex in densify]
    interpreter = tf.lite.Interpreter(
        model_path=src,
        experimental_op_resolver_type=tf.lite.experimental.OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES,
        experimental_preserve_all_tensors=True,
    )
    interpreter.allocate_tensors()
    for d in interpreter.get_input_details():
        interpreter.set_tensor(d["index"], np.zeros(d["shape"], d["dtype"]))
    interpreter.invoke()
    for op in ops:
        out = op.outputs[0]
        value = interpreter.get_tensor(out)
        buffer = schema.BufferT()
        buffer.data = np.frombuffer(value.tobytes(), dtype=np.uint8)
        model.buffers.append(buffer)
        graph.tensors[out].buffer = len(model.buffers) - 1
        # The sparse input is no longer used by any op.
        sparse = graph.tensors[op.inputs[0]]
        sparse.sparsity = None
        sparse.shape = list(value.shape)
        sparse.buffer = len(model.buffers) - 1
    graph.operators = [op for op in graph.operators if op.opcodeIndex not in densify]
    fb.write_model(model, dst)
    return len(ops)


def to_onnx(tflite, onnx_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "tf2onnx.convert",
            "--tflite",
            tflite,
            "--output",
            onnx_path,
            "--opset",
            "13",
        ],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def main():
    wheel, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(wheel) as z:
        detector = z.extract(DETECTOR, tmp)
        landmarks = z.extract(LANDMARKS, tmp)
        dense = os.path.join(tmp, "pose_detection_dense.tflite")
        n = densified(detector, dense)
        print(f"detector: {n} compressed weight tensors expanded")
        to_onnx(dense, os.path.join(out, "person_detector.onnx.part"))
        to_onnx(landmarks, os.path.join(out, "person_landmarks.onnx.part"))
    for name in ("person_detector.onnx", "person_landmarks.onnx"):
        os.replace(os.path.join(out, name + ".part"), os.path.join(out, name))
    print(f"wrote {out}/person_detector.onnx and {out}/person_landmarks.onnx")


if __name__ == "__main__":
    main()
