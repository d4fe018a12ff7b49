"""Simulated cells: the robot (`kinematics`), error terms and models (`errormodels`), the one measurement model
(`measurement`), what the sensor sees (`visibility`), simulated depth clouds and ICP (`cloud_registration`), the true
cell and the Monte Carlo (`montecarlo`), and the kernels vectorised over trials (`batch`, `compiled`)."""
