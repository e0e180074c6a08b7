"""Interchange with the immersive-video field: MPEG immersive-video content (MIV) out and in, IV-PSNR, USD cameras."""
