//! Serial line streams (skeleton).
