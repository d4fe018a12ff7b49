"""How rrbc runs: BLAS/OpenMP thread pools (`threads`, docs/threads.md) and the terminal progress bar (`progress`)."""
