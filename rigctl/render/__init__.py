"""Novel views from colour + disparity (depth-image-based rendering over the two-plane light field).

``inputs`` loads a rectified take or grid folder with a disparity folder (PFM files only: no dependence on
how the disparities were made), ``warp`` is the renderer (its compiled passes in ``kernels``), ``score``
holds PSNR/SSIM on the keyed subject, ``views`` writes novel views and runs leave-one-out, ``bench`` times a
stereo pair.
"""
