"""Lighting for inverse rendering: the capture's own environment estimated from its photos, and the
renderer's split-sum shading written again in torch so that materials can be fitted through it."""
