"""How rrbc runs: BLAS/OpenMP thread pools (`threads`, docs/threads.md) and where independent tasks run (`tasks`)."""
