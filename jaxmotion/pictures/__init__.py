"""Pictures of motion: still frames of observed motion and K futures (`viz`) and their animation (`animate`).

Only numpy and matplotlib: any layer that draws (a method's own pictures, the report of a run, the
viewer's thumbnails) imports these.
"""
