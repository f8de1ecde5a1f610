"""Whole-body skeleton tracking (MDCA): body model, likelihood, annealed particle filter."""
