"""lirm.engine.model: the LIRM network (paper §3): tokeniser, update transformer, hexa-plane neural
SDF with PBR heads and neural directional encoding (issue 4)."""
