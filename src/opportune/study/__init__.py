"""Studies: simulated runs of a plan under policies and bins, several products in one cell, their reports, and
lower bounds on what any policy can achieve."""
