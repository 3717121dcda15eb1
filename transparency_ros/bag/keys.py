"""custom_data keys this package writes into bags about the recording itself (the bag contract's
trial keys are in the README). Kept apart so readers need not import the writer."""

# a bag closed by Ctrl-C or SIGTERM: which signal ended it (an incomplete trial)
INTERRUPTED_KEY = "transparency.interrupted"
# a bag written by `transparency salvage`: where from, and what was lost
SALVAGED_KEY = "transparency.salvaged"
