"""Seed 004: star-sensor on-orbit calibration (docs/star_calibration.md).

Modules, in the order data flows:

* ``schema``     the star-sensor rig (``scenes/star_sensor.toml``) and its loader
* ``catalogue``  Hipparcos 2 (hip2.dat): parsing, proper motion, magnitude → photons
* ``attitude``   attitude sequences: inertial pointing, slews, random pointings
* ``field``      truth of a frame: which stars, where (true camera), how many photons
* ``analytic``   fast pixel-integrated Gaussian renderer (numpy)
* ``render_mitsuba``  the same frame through Mitsuba: a sky patch with the PSF baked in, seen
                 through the distorted ``rigsim_pinhole`` sensor (imports mitsuba lazily)
* ``render``     frames = photons → detector DN (+ truth for comparison)
* ``extract``    star extraction and centroiding (rigsim.imaging) on any DN frame
* ``identify``   identification near an approximate attitude
* ``calib``      AD / ADS measurement models, EKF over a sequence, batch least squares
* ``observability``  SVD of the Jacobians
* ``study``      Monte-Carlo comparison of AD and ADS (f known / biased / estimated)
* ``pipeline``, ``report``  the end-to-end run behind ``rigsim run star-calibration``

Importing this package imports neither mitsuba nor the catalogue file.
"""
