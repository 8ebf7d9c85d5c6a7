"""The ground-truth plant simulator (paper Fig. 1): recordings with known states and parameters."""
