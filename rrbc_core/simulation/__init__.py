"""Simulation of cells built from the models (`rrbc_core.models`): the true cell and the Monte Carlo
(`montecarlo`), and the kernels vectorised or compiled over trials (`batch`, `batch_registration`, `batch_checks`,
`compiled`, `compiled_annealing`)."""
