"""The paper's reproduction, beside the library: one module per experiment, the claims checklist, the
report (``hamsa reproduce``), the dataset matching benchmark (``hamsa benchmark-matching``) and the
terminal demo. The library (everything outside this subpackage) never imports it.
"""
