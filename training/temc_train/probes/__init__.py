"""Probes: the commands that measure trained models, data or the core and write a page
(`python -m temc_train.probes.<name>`): probe, leak_probe, keep_mean_probe,
prefilter_compare, n2n_cost, report. They import the library (temc_train) and each other;
the library never imports them."""
