"""temc's training package: model definitions, loss, colour transform, receptive field, ONNX export."""
