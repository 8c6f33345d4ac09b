"""Learning algorithms: consensus ADMM (discrete MOIRL), MOIQ and its baselines."""
