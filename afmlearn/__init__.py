"""afmlearn: from raw dynamic-AFM cantilever deflection to the tip-sample force."""

__version__ = "0.1.0"
