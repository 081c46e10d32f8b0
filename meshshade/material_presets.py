"""The measured material presets as plain data (no imports, so the command line lists their names in its help
before it imports numpy; :mod:`meshshade.materials` makes :class:`~meshshade.materials.Material` objects of them).

The presets (:data:`PRESETS`, every one in mm^-1 for the R, G, B channels):

* 12 from Table 2 of H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A Practical Model for Subsurface
  Light Transport", Proc. SIGGRAPH 2001, pp. 511-518 (the same values as pbrt-v3/v4's measured-media table,
  which cites that paper). All were measured with eta = 1.3 (Jensen et al. 2001, section 5). Mitsuba 0.6's copy
  of the table differs in a chicken sigma_a entry and stores the values in 1/cm-like scaled form; neither is
  repeated here.
* 30 from S. G. Narasimhan, M. Gupta, C. Donner, R. Ramamoorthi, S. K. Nayar, H. W. Jensen, "Acquiring Scattering
  Properties of Participating Media by Dilution", ACM Trans. Graph. 25(3) (Proc. SIGGRAPH 2006), pp. 1003-1012,
  Table 1, as sigma_s' = sigma_s (1 - g) and sigma_a: the values pbrt-v3/v4 ship in their measured-media table
  (pbrt-v4 src/pbrt/media.cpp). The paper measured liquids diluted in water; the index here is water's, 1.33
  (pbrt's default for these media too). Five of the table's media are left out: Coke, Pepsi, Merlot, Coors Light
  beer and grape juice have sigma_s' = 0 in at least one channel (clear liquids that scatter almost nothing:
  nothing a diffusion model can shade; :data:`NARASIMHAN_2006_LEFT_OUT`).
"""

#: name -> (sigma_s' [1/mm] RGB, sigma_a [1/mm] RGB); Jensen et al. 2001, Table 2; eta = 1.3 for all
JENSEN_2001_PRESETS = {
    "apple": ((2.29, 2.39, 1.97), (0.0030, 0.0034, 0.046)),
    "chicken1": ((0.15, 0.21, 0.38), (0.015, 0.077, 0.19)),
    "chicken2": ((0.19, 0.25, 0.32), (0.018, 0.088, 0.20)),
    "cream": ((7.38, 5.47, 3.15), (0.0002, 0.0028, 0.0163)),
    "ketchup": ((0.18, 0.07, 0.03), (0.061, 0.97, 1.45)),
    "marble": ((2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)),
    "potato": ((0.68, 0.70, 0.55), (0.0024, 0.0090, 0.12)),
    "skimmilk": ((0.70, 1.22, 1.90), (0.0014, 0.0025, 0.0142)),
    "skin1": ((0.74, 0.88, 1.01), (0.032, 0.17, 0.48)),
    "skin2": ((1.09, 1.59, 1.79), (0.013, 0.070, 0.145)),
    "spectralon": ((11.6, 20.4, 14.9), (0.00, 0.00, 0.00)),
    "wholemilk": ((2.55, 3.21, 3.77), (0.0011, 0.0024, 0.014)),
}
JENSEN_2001_ETA = 1.3

#: name -> (sigma_s' [1/mm] RGB, sigma_a [1/mm] RGB); Narasimhan et al. 2006, Table 1 (as pbrt-v3/v4's table)
NARASIMHAN_2006_PRESETS = {
    "lowfat-milk": ((0.89187, 1.5136, 2.532), (0.002875, 0.00575, 0.0115)),
    "reduced-milk": ((2.4858, 3.1669, 4.5214), (0.0025556, 0.0051111, 0.012778)),
    "regular-milk": ((4.5513, 5.8294, 7.136), (0.0015333, 0.0046, 0.019933)),
    "espresso": ((0.72378, 0.84557, 1.0247), (4.7984, 6.5751, 8.8493)),
    "mint-mocha-coffee": ((0.31602, 0.38538, 0.48131), (3.772, 5.8228, 7.82)),
    "lowfat-soy-milk": ((0.30576, 0.34233, 0.61664), (0.0014375, 0.0071875, 0.035937)),
    "regular-soy-milk": ((0.59223, 0.73866, 1.4693), (0.0019167, 0.0095833, 0.065167)),
    "lowfat-chocolate-milk": ((0.64925, 0.83916, 1.1057), (0.0115, 0.0368, 0.1564)),
    "regular-chocolate-milk": ((1.4585, 2.1289, 2.9527), (0.010063, 0.043125, 0.14375)),
    "sprite": ((6.0306e-06, 6.4139e-06, 6.5504e-06), (0.001886, 0.0018308, 0.0020025)),
    "gatorade": ((0.0024574, 0.003007, 0.0037325), (0.024794, 0.019289, 0.008878)),
    "chardonnay": ((1.7982e-05, 1.3758e-05, 1.2023e-05), (0.010782, 0.011855, 0.023997)),
    "white-zinfandel": ((1.7501e-05, 1.9069e-05, 1.288e-05), (0.012072, 0.016184, 0.019843)),
    "budweiser-beer": ((2.4356e-05, 2.4079e-05, 1.0564e-05), (0.011492, 0.024911, 0.057786)),
    "clorox": ((0.0024035, 0.0031373, 0.003991), (0.0033542, 0.014892, 0.026297)),
    "apple-juice": ((0.00013612, 0.00015836, 0.000227), (0.012957, 0.023741, 0.052184)),
    "cranberry-juice": ((0.00010402, 0.00011646, 7.8139e-05), (0.039437, 0.094223, 0.12426)),
    "ruby-grapefruit-juice": ((0.011002, 0.010927, 0.011036), (0.085867, 0.18314, 0.25262)),
    "white-grapefruit-juice": ((0.22826, 0.23998, 0.32748), (0.0138, 0.018831, 0.056781)),
    "shampoo": ((0.0007176, 0.0008303, 0.0009016), (0.014107, 0.045693, 0.061717)),
    "strawberry-shampoo": ((0.00015671, 0.00015947, 1.518e-05), (0.01449, 0.05796, 0.075823)),
    "head-and-shoulders-shampoo": ((0.023805, 0.028804, 0.034306), (0.084621, 0.15688, 0.20365)),
    "lemon-tea-powder": ((0.040224, 0.045264, 0.051081), (2.4288, 4.5757, 7.2127)),
    "orange-powder": ((0.00015617, 0.00017482, 0.0001762), (0.001449, 0.003441, 0.007863)),
    "pink-lemonade-powder": ((0.00012103, 0.00013073, 0.00012528), (0.001165, 0.002366, 0.003195)),
    "cappuccino-powder": ((1.8436, 2.5851, 2.1662), (35.844, 49.547, 61.084)),
    "salt-powder": ((0.027333, 0.032451, 0.031979), (0.28415, 0.3257, 0.34148)),
    "sugar-powder": ((0.00022272, 0.00025513, 0.000271), (0.012638, 0.031051, 0.050124)),
    "suisse-mocha-powder": ((2.7979, 3.5452, 4.3365), (17.502, 27.004, 35.433)),
    "pacific-ocean-surface-water": ((0.0001764, 0.00032095, 0.00019617), (0.031845, 0.031324, 0.030147)),
}
#: water, the medium the dilutions were measured in
NARASIMHAN_2006_ETA = 1.33
#: media of Narasimhan et al. 2006 (in pbrt's table) that are not presets, and why
NARASIMHAN_2006_LEFT_OUT = {name: "sigma_s' = 0 in at least one channel (a clear liquid: no diffusion)"
                            for name in ("coke", "pepsi", "merlot", "coors-light-beer", "grape-juice")}

#: every preset: name -> (sigma_s' RGB, sigma_a RGB, eta, source), Jensen et al. 2001 first
PRESETS = {
    **{k: (s, a, JENSEN_2001_ETA, "Jensen et al. 2001") for k, (s, a) in JENSEN_2001_PRESETS.items()},
    **{k: (s, a, NARASIMHAN_2006_ETA, "Narasimhan et al. 2006") for k, (s, a) in NARASIMHAN_2006_PRESETS.items()},
}

