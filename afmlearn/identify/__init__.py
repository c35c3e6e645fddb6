"""Sparse-regression identification of the tip-sample force from deflection traces."""
