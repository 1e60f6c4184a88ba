"""lirm.engine.capture: photos, video or camera frames -> posed, masked, cropped views (issue 3)."""
