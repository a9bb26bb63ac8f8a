"""Drake LeafSystems and diagram builders of the hand-eye servoing simulation."""
