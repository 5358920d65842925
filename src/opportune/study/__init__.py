"""Studies: simulated runs of a plan under policies and bins, several products in one cell, and their reports."""
