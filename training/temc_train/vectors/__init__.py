"""Vector writers: the commands that write the test vectors the Rust core and training both
check against, under ../tests/data (`python -m temc_train.vectors.<name>`): recon_vectors,
feature_vectors, keep_mean. They import the library (temc_train) only; the library never
imports them."""
