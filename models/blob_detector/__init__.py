"""The classical blob-contrast detector as an ONNX graph (a reference model for tests and the first SITL)."""
