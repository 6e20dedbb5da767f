"""The research record's code: analyses the product does not ship, kept to be run again.

The product (`fahv`) never imports this package (an import contract of pyproject.toml);
it imports the product. Its command is `fahv-studies` (`fahv_studies.cli`); its results
are the documentation's studies page (docs/results/studies.md) and the theory pages
that cite them.

- `fahv_studies.estimation`: what can be certified about the loop on the Kalman
  estimate: the bounds of the filter's error (covariance over every pair of model and
  gain vertex, the frozen vertices' worst cases), whether a set-based output-feedback
  tube fits the inputs' room, and the probabilistic tube of the loop as it flies.
"""
