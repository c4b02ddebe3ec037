"""The docs pages rendered from the committed metrics (``make docs``): ``pages`` (the toy's page,
the README's result block, the verdict's page through ``verdict_page``), ``markdown`` (numbers,
tables and prose)."""
