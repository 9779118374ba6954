"""temc's training package: model definitions, loss, colour transform, ONNX export."""
