"""The models of the physical cell, below everything that simulates or files them: the robot arm (`kinematics`),
error terms and error models (`errormodels`, `errorterms`), the one measurement model (`measurement`), what the
sensor sees (`visibility`) and simulated depth clouds with ICP (`cloud_registration`)."""
