"""Research tools of the arm's skill recipes: a scripted top-down grasp (:mod:`~hrlp.arm.research.scripted`),
imitation of it (:mod:`~hrlp.arm.research.imitate`), DAgger rounds on a Manager's hand-over states
(:mod:`~hrlp.arm.research.dagger`) and banks of start states (:mod:`~hrlp.arm.research.starts`). The shipped skills'
recipes use them; the generic hierarchy does not."""
