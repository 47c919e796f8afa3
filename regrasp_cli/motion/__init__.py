"""Motion primitives shared by the planners and the validator: segment sampling and its
reach bounds (:mod:`.local`), RRT-Connect and shortcut (:mod:`.rrt`), timing (:mod:`.timing`)."""
