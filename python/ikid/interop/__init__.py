"""Model files for other biomechanics tools, written from ikid's body model (``ikid.body_model``).

One module per tool; each writes text with the standard library, so ``import ikid`` never
needs the tool itself (the tests and evaluation targets install it to check the files).
"""
