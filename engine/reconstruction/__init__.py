"""Running LIRM updates on a prepared capture: views to tensors, the update loop, what it writes."""
