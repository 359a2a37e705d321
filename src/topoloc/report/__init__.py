"""Pages generated from the pipeline's outputs: the docs site's results pages and the README's headline tables."""
