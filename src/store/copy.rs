//! `rackd db copy`: moves a site's store from one database to another.
