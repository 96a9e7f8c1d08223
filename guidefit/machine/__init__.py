"""The machine level (the paper's Sec. 4): the identified joints in a whole-machine FE model.

``correlate`` compares FE with test modes (Eq. 34, MAC pairing; the FE readers are in
:mod:`guidefit.io.fe_results`); ``ccx_deck`` finds, scales and runs the guidefit joints of a
CalculiX deck; ``update`` adjusts the joints so that the machine's FE modes meet its measured ones.
"""
