//! The macro's unit tests, one file per thing tested: the symbolic
//! engine's tables (`tables`), what is emitted (`emission`), the messages
//! of a refused declaration (`messages`), and the limits that keep hostile
//! input a compile error (`limits`, on the sources of `hostile`).

mod emission;
mod hostile;
mod limits;
mod messages;
mod tables;
