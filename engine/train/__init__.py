"""Training LIRM: losses over rendered ray batches and the training loops."""
