"""temc's training package, in four walls.

- `temc_train` (this folder): the library. Models, the reconstruction and keep-mean stage,
  loss, colour, data sets and batches, metrics (evaluate), receptive field, graph fusion,
  ONNX export (onnx_export) and the one reader and writer of runs (checkpoint.Checkpoint).
  No entry points.
- `temc_train.drivers`: the commands that make things: train, export, ship, budget, shard,
  ready (and distributed, train's process group).
- `temc_train.probes`: the commands that measure and write a page: probe, leak_probe,
  keep_mean_probe, prefilter_compare, n2n_cost, report.
- `temc_train.vectors`: the commands that write the shared test vectors under
  ../tests/data (recon_vectors, feature_vectors, keep_mean).

The rule: the library never imports drivers, probes or vectors (tests/test_walls.py checks
it); those import the library and, within their own wall, each other.
"""
