"""v0 and w0: the paper's closed form and the maximum-likelihood fit."""
