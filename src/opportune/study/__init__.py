"""Studies of policies: simulations, reports and bounds on what any policy can achieve."""
