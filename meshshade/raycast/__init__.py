"""Ray casting: the only Embree users. ``scene`` (Embree adapter and its numpy twin), ``embree_direct`` (the
Monte Carlo engine's direct binding of Embree's ``rtcIntersect1``)."""
