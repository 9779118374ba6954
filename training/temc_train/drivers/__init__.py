"""Drivers: the commands that train, export and ship models (`python -m
temc_train.drivers.<name>`): train (with distributed, its process group), export, ship,
budget, shard, ready. They import the library (temc_train) and each other; the library
never imports them."""
