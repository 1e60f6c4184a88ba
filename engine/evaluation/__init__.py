"""`lirm eval`: the paper's tables on held-out sets, after each progressive update."""
